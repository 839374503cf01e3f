"""Starting the entry points as a user would (``python scripts/<name>.py``), each in its own process
group so that a test can signal it and then see whether anything of it (workers, job tasks) is left."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def processes_in_group(pgid: int) -> list[int]:
    """Live (not zombie) processes of process group ``pgid``, read from ``/proc`` (Linux; psutil is
    not a dependency): what a stopped command must not leave behind (its workers are in its group)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # the process ended while we looked
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            found.append(int(stat.parent.name))
    return found


class Started:
    """A running script: ``proc`` (its pid is the process group id) and its output, in a file (a pipe
    nobody reads while waiting would fill up and block the script)."""

    def __init__(self, proc: subprocess.Popen, out: Path) -> None:
        self.proc, self.out = proc, out

    @property
    def pid(self) -> int:
        return self.proc.pid

    def output(self) -> str:
        return self.out.read_text(errors="replace")

    def wait(self, timeout: float) -> int:
        """The exit code; a script still running after ``timeout`` seconds fails the test (its output
        tail in the message)."""
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"still running after {timeout} s:\n{self.output()[-3000:]}") from None

    def left(self, grace: float = 10.0) -> list[int]:
        """Processes of the group still alive ``grace`` seconds after the script ended at the latest."""
        deadline = time.monotonic() + grace
        while processes_in_group(self.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        return processes_in_group(self.pid)

    def kill_group(self) -> None:
        try:
            os.killpg(self.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait()


def _as_at_a_terminal() -> None:
    """Ctrl-C's default action, as a command typed at a terminal has it. A shell script that starts
    pytest with ``&`` (``nohup ... &``) makes SIGINT ignored for everything below it, and Python then
    installs no KeyboardInterrupt handler: a SIGINT test would see the script ignore its signal."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start_script(
    name: str, args: list[str], cwd: Path, out: Path, env: dict[str, str] | None = None
) -> Started:
    """``python scripts/<name>.py *args`` in a new session (its own process group), output to ``out``,
    with SIGINT's default action whatever pytest inherited."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1", **(env or {})}
    with open(out, "ab") as f:
        proc = subprocess.Popen(
            [sys.executable, str(ROOT / "scripts" / f"{name}.py"), *args],
            cwd=cwd,
            env=env,
            stdout=f,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            preexec_fn=_as_at_a_terminal,
        )
    return Started(proc, out)


def in_group(pgid: int, needle: str) -> list[int]:
    """Processes of group ``pgid`` whose command line contains ``needle``."""
    found = []
    for pid in processes_in_group(pgid):
        try:
            if needle.encode() in Path(f"/proc/{pid}/cmdline").read_bytes():
                found.append(pid)
        except OSError:  # ended meanwhile
            continue
    return found


def wait_for(probe: Callable[[], Any], timeout: float, started: Started | None = None) -> Any:
    """The first non-None ``probe()``, polled until ``timeout`` seconds; fails early if ``started``
    ended before (what the test waits for will then never come)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if (found := probe()) is not None:
            return found
        if started is not None and started.proc.poll() is not None:
            raise AssertionError(
                f"ended (exit {started.proc.returncode}) before the awaited state:\n"
                f"{started.output()[-3000:]}"
            )
        time.sleep(0.3)
    raise TimeoutError(f"nothing after {timeout} s")
