"""Every entry point exits: ``rlgrasp-eval``, the sweep and ``rlgrasp-export`` run to the end, or stop
on a signal midway, within a timeout, with a clear exit status, leaving no process of their group
(pool workers, collector workers) behind. Training and the resume of a finished run: tests/test_resume.py."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from tests.procs import in_group, wait_for
from tests.test_eval import make_run

QUIET_EVAL = ["video=false", "plots=false", "tensorboard=false"]


def test_eval_runs_to_the_end_and_exits(tmp_path: Path, script) -> None:
    run = make_run(tmp_path)
    done = script("evaluate", f"ckpt={run}", "episodes=4", "workers=2", "name=done", *QUIET_EVAL)
    assert done.wait(timeout=180) == 0, done.output()[-2000:]
    assert (run / "eval" / "done" / "metrics.json").is_file()
    assert done.left() == []


@pytest.mark.parametrize(
    ("sig", "to_group"),
    [(signal.SIGTERM, False),  # `kill <pid>`, a scheduler: the pool workers were left running, orphaned
     (signal.SIGINT, True)],  # Ctrl-C at a terminal: the whole group gets it
    ids=["sigterm-to-main", "sigint-to-group"],
)
def test_eval_stopped_midway_exits_and_leaves_nothing(
    tmp_path: Path, script, sig: int, to_group: bool
) -> None:
    run = make_run(tmp_path)
    stopped = script("evaluate", f"ckpt={run}", "episodes=2000", "workers=2", "name=stopped", *QUIET_EVAL)
    wait_for(lambda: True if len(in_group(stopped.pid, "spawn_main")) == 2 else None, 180, stopped)
    time.sleep(3)  # the pool workers are starting or running episodes (2,000 take minutes)
    if to_group:
        os.killpg(stopped.pid, sig)
    else:
        stopped.proc.send_signal(sig)
    assert stopped.wait(timeout=60) == 128 + sig, stopped.output()[-2000:]
    out = stopped.output()
    assert f"error: stopped by {signal.Signals(sig).name}; the evaluation was not written" in out
    assert "Traceback" not in out, out[-3000:]
    assert not (run / "eval").exists()  # neither the output folder nor its staging folder
    assert stopped.left() == []


def test_export_runs_to_the_end_and_exits(tmp_path: Path, script) -> None:
    pytest.importorskip("onnxruntime")
    run = make_run(tmp_path)
    done = script("export", f"ckpt={run}", "format=all", "verify_obs=100")
    assert done.wait(timeout=300) == 0, done.output()[-2000:]
    assert {p.name for p in (run / "export").glob("policy.*")} >= {"policy.pt", "policy.onnx", "policy.pt2"}
    assert done.left() == []
