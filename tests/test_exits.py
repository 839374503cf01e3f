"""Every entry point exits: ``rlgrasp-eval``, the sweep and ``rlgrasp-export`` run to the end, or stop
on a signal midway, within a timeout, with a clear exit status, leaving no process of their group
(pool workers, collector workers, training's evaluation process) behind. Training and the resume of a
finished run: tests/test_resume.py."""

from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

import optuna
import pytest

from rlgrasp.sweep.study import ATTR_INTERRUPTED, ATTR_RETRY_OF
from tests.helpers import make_run
from tests.procs import in_group, wait_for

QUIET_EVAL = ["video=false", "plots=false", "tensorboard=false"]


@pytest.mark.full  # quick set: test_eval_stopped_midway_exits_and_leaves_nothing[sigint-to-group]
def test_eval_runs_to_the_end_and_exits(tmp_path: Path, script) -> None:
    run = make_run(tmp_path)
    done = script("evaluate", f"ckpt={run}", "episodes=4", "workers=2", "name=done", *QUIET_EVAL)
    assert done.wait(timeout=180) == 0, done.output()[-2000:]
    assert (run / "eval" / "done" / "metrics.json").is_file()
    assert done.left() == []


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
@pytest.mark.parametrize(
    ("sig", "to_group"),
    # `kill <pid>`, a scheduler: the main process only; its pool must end too
    [
        pytest.param(signal.SIGTERM, False, marks=pytest.mark.full),
        (signal.SIGINT, True),
    ],  # Ctrl-C at a terminal: the whole group gets it
    ids=["sigterm-to-main", "sigint-to-group"],
)
def test_eval_stopped_midway_exits_and_leaves_nothing(
    tmp_path: Path, script, sig: int, to_group: bool
) -> None:
    run = make_run(tmp_path)
    stopped = script("evaluate", f"ckpt={run}", "episodes=2000", "workers=2", "name=stopped", *QUIET_EVAL)
    wait_for(lambda: True if len(in_group(stopped.pid, "spawn_main")) == 2 else None, 180, stopped)
    time.sleep(1)  # the workers are importing torch: a signal there must not print their tracebacks
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


@pytest.mark.full  # waits for the progress line of a 2,000-episode evaluation
def test_eval_whose_worker_is_killed_exits_with_one_line_and_leaves_nothing(tmp_path: Path, script) -> None:
    run = make_run(tmp_path)
    hit = script("evaluate", f"ckpt={run}", "episodes=2000", "workers=2", "name=hit", *QUIET_EVAL)
    workers = wait_for(lambda: w if len(w := in_group(hit.pid, "spawn_main")) == 2 else None, 180, hit)
    wait_for(lambda: re.search(r"\d+/2000 episodes", hit.output()), 180, hit)  # mid-evaluation
    os.kill(workers[0], signal.SIGKILL)  # as the out-of-memory killer or a crash in PyBullet would
    assert hit.wait(timeout=60) == 1, hit.output()[-2000:]
    out = hit.output()
    assert "error: a worker process died" in out and "the evaluation was not written" in out
    assert "Traceback" not in out, out[-3000:]
    assert not (run / "eval").exists()
    assert hit.left() == []


def _trials(root: Path) -> list[optuna.trial.FrozenTrial]:
    storage = optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(str(root / "smoke" / "journal.log"))
    )
    return optuna.load_study(study_name="smoke", storage=storage).get_trials()


@pytest.mark.full  # two sweep processes, one trial of 8,192 frames
def test_sweep_stops_on_sigterm_then_the_same_command_finishes(tmp_path: Path, script) -> None:
    """SIGTERM during a trial (collector workers running): the trial saves, the sweep stops with 130 and
    is resumable; the same command then runs to the end. Training hands the SIGTERM on: kept to itself,
    the trial would end early as COMPLETE with a half-trained value and the sweep go on."""
    root = tmp_path / "sweeps"
    cmd = [
        "experiment=smoke",
        "sweep=smoke",
        f"sweep.root_dir={root}",
        "sweep.n_trials=1",
        "sweep.plots=false",
        "sweep.trial.total_frames=8192",  # the signal lands mid-run however fast the collector runs
        # the smoke experiment's process collector (one worker, 512-frame batches), not collector=single
        'sweep.overrides=["collector.num_workers=1","eval.interval_frames=512","eval.episodes=4","logger=none"]',
    ]
    first = script("sweep", *cmd)
    log = root / "smoke" / "trials" / "0000" / "train.log"
    wait_for(lambda: True if log.is_file() and "frames 512/" in log.read_text() else None, 240, first)
    first.proc.send_signal(signal.SIGTERM)
    assert first.wait(timeout=90) == 130, first.output()[-3000:]
    assert re.search(r"SIGTERM at [\d,]+ frames: saving a checkpoint", log.read_text())
    assert first.left() == []
    (trial,) = _trials(root)
    assert trial.state.name == "FAIL" and trial.user_attrs[ATTR_INTERRUPTED] is True

    second = script("sweep", *cmd)
    assert second.wait(timeout=300) == 0, second.output()[-3000:]
    assert second.left() == []
    trials = _trials(root)
    assert [t.state.name for t in trials] == ["FAIL", "COMPLETE"]
    assert trials[1].user_attrs[ATTR_RETRY_OF] == 0


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_export_runs_to_the_end_and_exits(tmp_path: Path, script) -> None:
    pytest.importorskip("onnxruntime")
    run = make_run(tmp_path)
    done = script("export", f"ckpt={run}", "format=all", "verify_obs=100")
    assert done.wait(timeout=300) == 0, done.output()[-2000:]
    assert {p.name for p in (run / "export").glob("policy.*")} >= {"policy.pt", "policy.onnx", "policy.pt2"}
    assert done.left() == []


@pytest.mark.slow
@pytest.mark.parametrize("to_group", [False, True], ids=["sigterm-to-main", "sigterm-to-group"])
def test_training_stopped_mid_background_evaluation_exits_and_leaves_nothing(
    tmp_path: Path, script, to_group: bool
) -> None:
    """SIGTERM while the evaluation process runs a long evaluation (training may be waiting for it):
    to the main process (`kill`), or to the whole group (a scheduler); the run saves its checkpoint and
    exits 0 within a timeout, and its evaluation process and workers end with it."""
    run = tmp_path / "run"
    started = script(
        "train",
        "experiment=smoke",
        "collector.steps_per_env=64",
        "eval.background=true",
        "eval.interval_frames=256",
        "eval.episodes=400",
        "total_frames=100000",
        "logger=none",
        f"hydra.run.dir={run}",
    )
    evaluating = "periodic evaluations run in process"
    wait_for(lambda: True if evaluating in started.output() else None, 600, started)  # a loaded machine
    time.sleep(5)  # 400 episodes take minutes: the learner collects, then waits for them at 512 frames
    if to_group:
        os.killpg(started.pid, signal.SIGTERM)
    else:
        started.proc.send_signal(signal.SIGTERM)
    # The batches in flight are collected first: seconds, minutes on a machine busy with other work.
    assert started.wait(timeout=300) == 0, started.output()[-3000:]
    out = started.output()
    assert re.search(r"SIGTERM at [\d,]+ frames: saving a checkpoint", out), out[-3000:]
    assert "Traceback" not in out, out[-3000:]
    assert started.left() == []  # the evaluation process is of the group too


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_eval_killed_with_sigkill_leaves_no_worker(tmp_path: Path, script) -> None:
    """``kill -9`` (the OOM killer's signal) gives the parent no chance to end its pool: the
    workers end themselves (``rlgrasp.utils.die_with_parent``)."""
    run = make_run(tmp_path)
    killed = script("evaluate", f"ckpt={run}", "episodes=2000", "workers=2", "name=killed", *QUIET_EVAL)
    # Each worker's physics client says "argv[0]=" once it is set up: both are into their episodes.
    started = lambda: killed.output().partition("evaluating")[2].count("argv[0]=") >= 2 or None  # noqa: E731
    wait_for(started, 180, killed)
    killed.proc.send_signal(signal.SIGKILL)
    killed.wait(timeout=30)
    deadline = time.monotonic() + 5
    while in_group(killed.pid, "spawn_main") and time.monotonic() < deadline:
        time.sleep(0.2)
    assert in_group(killed.pid, "spawn_main") == []


def _demos_working(tmp_path: Path, script):
    started = script("demos", "episodes=100", f"out={tmp_path / 'demos_out'}", "workers=2")
    workers = wait_for(
        lambda: w if len(w := in_group(started.pid, "spawn_main")) == 2 else None, 180, started
    )
    wait_for(lambda: re.search(r"\d+/100 episodes", started.output()), 180, started)  # mid-recording
    return started, workers


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_demos_stopped_with_sigterm_exits_with_one_line_and_leaves_nothing(tmp_path: Path, script) -> None:
    started, _ = _demos_working(tmp_path, script)
    started.proc.send_signal(signal.SIGTERM)  # `kill <pid>`: the main process only
    assert started.wait(timeout=60) == 128 + signal.SIGTERM, started.output()[-2000:]
    out = started.output()
    assert "error: stopped by SIGTERM; nothing was written" in out and "Traceback" not in out, out[-3000:]
    assert not (tmp_path / "demos_out" / "demos").exists()
    assert started.left() == []
