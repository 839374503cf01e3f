"""``kill -9`` of a command at fixed times after its launch, and what of it is still alive 2 s later.

    python benchmarks/bench_orphans.py [--delays 0.5 1 2 4 8] [--commands eval demos train] [--after 2]

Each command starts in its own process group (as a shell would start it), is sent SIGKILL ``delay``
seconds after its launch (its workers may be importing, building envs, or in their episodes then;
on a loaded machine a command may not have started any yet), and once more the moment its first
worker exists (``first worker``: still importing, the case a worker's own watch came too late for),
and the group is read from ``/proc`` ``--after`` seconds later: every process still alive there is
an orphan (rlgrasp.utils.guard_spawned_children, die_with_parent). Prints a Markdown table; exit
code 1 if any orphan was left. What is left is killed before the next row.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
SHIPPED = ROOT / "policies" / "grasp_ppo.pt"


def commands(out: Path) -> dict[str, list[str]]:
    """Each command as a user types it: the installed console scripts, and ``scripts/train.py``."""
    return {
        "eval": [
            str(BIN / "rlgrasp-eval"),
            f"ckpt={SHIPPED}",
            "episodes=400",
            "workers=2",
            f"out_dir={out / 'eval'}",
            "video=false",
            "plots=false",
            "tensorboard=false",
        ],
        "demos": [str(BIN / "rlgrasp-demos"), "episodes=400", "workers=2", f"out={out / 'demos'}"],
        "train": [
            sys.executable,
            str(ROOT / "scripts" / "train.py"),
            "experiment=smoke",
            "collector.num_workers=2",
            "total_frames=1000000",
            "logger=none",
            f"paths.output_dir={out / 'train'}",
        ],
    }


def group_alive(pgid: int) -> list[int]:
    """Live (not zombie) processes of process group ``pgid`` (``/proc``; Linux)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            found.append(int(stat.parent.name))
    return found


def _spawned(pgid: int) -> bool:
    """Whether a spawned worker of group ``pgid`` exists (its command line runs ``spawn_main``)."""
    for pid in group_alive(pgid):
        try:
            if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                return True
        except OSError:
            continue
    return False


def kill_after(argv: list[str], delay: float | None, after: float, cwd: Path) -> tuple[int, list[int]]:
    """Start ``argv`` in a new process group, SIGKILL it ``delay`` s later (None: as soon as its first
    worker exists), and return how many processes the group had then and the ones still alive
    ``after`` s after the kill."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    with open(cwd / "output.log", "wb") as log:  # read when a row looks wrong
        proc = subprocess.Popen(
            argv, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
    if delay is None:  # the moment the first worker exists: it is still importing, not yet watching
        deadline = time.monotonic() + 120
        while not _spawned(proc.pid) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.02)
    else:
        time.sleep(delay)
    at_kill = len(group_alive(proc.pid))
    proc.kill()
    proc.wait()  # reaped: only its children can be left
    time.sleep(after)
    left = group_alive(proc.pid)
    for pid in left:  # the next row starts clean
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return at_kill, left


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--delays", type=float, nargs="+", default=[0.5, 1, 2, 4, 8])
    parser.add_argument("--commands", nargs="+", default=["eval", "demos", "train"])
    parser.add_argument("--after", type=float, default=2.0, help="seconds after the kill to look")
    args = parser.parse_args(argv)
    rows, orphans = [], 0
    with tempfile.TemporaryDirectory(prefix="bench_orphans_") as tmp:
        print(f"outputs in {tmp} (removed at the end)", file=sys.stderr)
        for name in args.commands:
            for delay in [*args.delays, None]:
                out = Path(tmp) / f"{name}_{delay}"
                out.mkdir()
                at_kill, left = kill_after(commands(out)[name], delay, args.after, out)
                orphans += len(left)
                when = "first worker" if delay is None else f"{delay:g}"
                rows.append(f"| {name} | {when} | {at_kill} | {len(left)} |")
                print(rows[-1], flush=True)
    print(f"\n| command | kill -9 at (s) | processes at the kill | alive {args.after:g} s later |")
    print("|---|---|---|---|")
    print("\n".join(rows))
    return 1 if orphans else 0


if __name__ == "__main__":
    sys.exit(main())
