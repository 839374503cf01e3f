"""No process of a command outlives it: ``kill -9`` of ``rlgrasp-eval`` while its workers are still
importing (before they could watch their parent), and a while later, leaves nothing alive 2 s on
(``rlgrasp.utils.guard_spawned_children``: each spawned child knows its parent's pid from before it
started). ``benchmarks/bench_orphans.py`` runs the same for rlgrasp-demos and scripts/train.py at
0.5-8 s."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rlgrasp.utils import guard_spawned_children
from tests.procs import ROOT, in_group, processes_in_group

SHIPPED = ROOT / "policies" / "grasp_ppo.pt"
EVAL = Path(sys.executable).parent / "rlgrasp-eval"


def _eval(tmp_path: Path) -> subprocess.Popen:
    args = [f"ckpt={SHIPPED}", "episodes=400", "workers=2", f"out_dir={tmp_path / 'eval'}"]
    return subprocess.Popen(
        [str(EVAL), *args, "video=false", "plots=false", "tensorboard=false"],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def _left_after_kill(proc: subprocess.Popen, after: float = 2.0) -> list[int]:
    proc.kill()
    proc.wait()
    time.sleep(after)
    left = processes_in_group(proc.pid)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    return left


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
@pytest.mark.parametrize("when", ["workers importing", "1.5 s"])
def test_kill_9_of_rlgrasp_eval_leaves_no_process(tmp_path: Path, when: str) -> None:
    proc = _eval(tmp_path)
    if when == "workers importing":  # the moment the first worker exists: it is still importing
        deadline = time.monotonic() + 60
        while not in_group(proc.pid, "spawn_main") and time.monotonic() < deadline:
            time.sleep(0.02)
        assert in_group(proc.pid, "spawn_main"), "no worker was started"
    else:
        time.sleep(1.5)
    assert _left_after_kill(proc) == []


def _sleep(seconds: float) -> None:
    time.sleep(seconds)


def _spawn_and_hang(ready: Path) -> None:
    """A parent that spawns a child which then sleeps for a minute, and says so."""
    guard_spawned_children()
    child = multiprocessing.get_context("spawn").Process(target=_sleep, args=(60,))
    child.start()
    ready.write_text(str(child.pid))
    time.sleep(60)


def test_a_child_whose_parent_died_before_it_started_ends(tmp_path: Path) -> None:
    """The parent is gone before the child has run one line of its own: the child must not take its
    new parent (pid 1, a subreaper) for its own and wait on it."""
    ready = tmp_path / "child_pid"
    parent = multiprocessing.get_context("spawn").Process(target=_spawn_and_hang, args=(ready,))
    parent.start()
    deadline = time.monotonic() + 60
    while not ready.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    child = int(ready.read_text())
    os.kill(parent.pid, signal.SIGKILL)  # the child is still starting its interpreter
    parent.join()
    time.sleep(2.0)
    try:
        os.kill(child, 0)
        alive = Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (ProcessLookupError, FileNotFoundError):
        alive = False
    if alive:
        os.kill(child, signal.SIGKILL)
    assert not alive
