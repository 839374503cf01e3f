"""Optuna sweeps: search space from config, a failing and a pruned trial, interruption and resume,
summary and best config. The trials are the smoke experiment on 1,024 frames, in-process."""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import optuna
import pytest

from rlgrasp.sweep.cli import is_sweep_override, main
from rlgrasp.sweep.runner import run_sweep
from rlgrasp.sweep.space import parse_space, to_overrides
from rlgrasp.sweep.study import ATTR_INTERRUPTED, ATTR_RETRY_OF

ROOT = Path(__file__).resolve().parents[1]


def test_space_parses_nested_params_and_names_bad_keys() -> None:
    space = parse_space(
        {
            "algo": {"lr": {"type": "float", "low": 1e-4, "high": 1e-3, "log": True}},
            "model": {"hidden_sizes": {"type": "categorical", "choices": [[64, 64], [128]]}},
            "collector": {"envs_per_worker": {"type": "int", "low": 2, "high": 8, "step": 2}},
        }
    )
    assert set(space) == {"algo.lr", "model.hidden_sizes", "collector.envs_per_worker"}
    assert space["model.hidden_sizes"].choices == ("[64,64]", "[128]")
    assert to_overrides({"algo.lr": 0.1, "a.b": None, "c": True}) == ["algo.lr=0.1", "a.b=null", "c=true"]
    with pytest.raises(ValueError, match="algo.lr: type float needs 'high'"):
        parse_space({"algo": {"lr": {"type": "float", "low": 1.0}}})
    with pytest.raises(ValueError, match="algo.lr"):
        parse_space({"algo": {"lr": {"type": "gauss"}}})
    assert is_sweep_override("sweep.n_trials=3") and is_sweep_override("+sweep.x=1")
    assert not is_sweep_override("sweeper=1") and not is_sweep_override("algo.lr=1")


def _wait_for(path: Path, text: str, proc: subprocess.Popen, timeout: float = 240) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.is_file() and text in path.read_text():
            return
        assert proc.poll() is None, "the sweep ended before it could be interrupted"
        time.sleep(0.2)
    raise TimeoutError(f"{text!r} never appeared in {path}")


def test_sweep_fails_prunes_resumes_and_summarizes(tmp_path: Path) -> None:
    root = tmp_path / "sweeps"
    sweep = [
        "sweep=smoke",
        f"sweep.root_dir={root}",
        "sweep.n_trials=3",
        "sweep.plots=false",
        # trial 0 crashes (unknown control mode), trial 1 runs as sampled
        "sweep.enqueue=[{env:{control_mode:bogus}},{algo:{epochs:1}}]",
    ]
    train = ["experiment=smoke"]
    study_dir = root / "smoke"
    # 1) a sweep process, interrupted (SIGINT) during trial 2 once it has evaluated
    proc = subprocess.Popen(
        [sys.executable, str(ROOT / "scripts" / "sweep.py"), *sweep, "sweep.pruner.name=none", *train],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        _wait_for(study_dir / "trials" / "0002" / "train.log", "eval at 512 frames", proc)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, out[-3000:]
    storage = optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(str(study_dir / "journal.log"))
    )
    trials = optuna.load_study(study_name="smoke", storage=storage).get_trials()
    assert [t.state.name for t in trials] == ["FAIL", "COMPLETE", "FAIL"]
    assert "control" in trials[0].user_attrs["error"]
    assert trials[2].user_attrs[ATTR_INTERRUPTED] is True
    assert (study_dir / "trials" / "0002" / "checkpoints" / "last.pt").is_file()  # saved on SIGINT
    assert (study_dir / "trials.csv").is_file()  # the summary is written on interruption too

    # 2) the same command resumes: trial 2's parameters run again (retry), here under a pruner
    # that stops it at its first eval; the on_eval callback saves a checkpoint before it stops.
    result = run_sweep(
        [*sweep, "sweep.pruner.name=threshold", "+sweep.pruner.kwargs.lower=1.0e9"], train
    )
    assert not result["interrupted"] and result["finished"] == 3
    trials = optuna.load_study(study_name="smoke", storage=storage).get_trials()
    assert [t.state.name for t in trials] == ["FAIL", "COMPLETE", "FAIL", "PRUNED"]
    assert trials[3].user_attrs[ATTR_RETRY_OF] == 2 and trials[3].params == trials[2].params
    assert trials[3].last_step == 512
    assert (study_dir / "trials" / "0003" / "checkpoints" / "ckpt_0000000512.pt").is_file()

    # 3) summary: tables and the best trial (1) as a ready-to-run experiment config
    with (study_dir / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["state"] for r in rows] == ["FAIL", "COMPLETE", "FAIL", "PRUNED"]
    assert "retry of 2" in rows[3]["note"] and "interrupted" in rows[2]["note"]
    assert re.search(r"\| 1 +\| COMPLETE +\|", (study_dir / "trials.md").read_text())
    best = result["best_config"]
    assert result["best_number"] == 1 and best == study_dir / "configs" / "experiment" / "smoke_best.yaml"
    job = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "train.py"), "--config-dir", str(best.parents[1]),
         "experiment=smoke_best", "--cfg", "job"],
        capture_output=True, text=True, check=True, cwd=tmp_path,
    ).stdout
    assert "experiment_name: smoke_best" in job and "collectors.SingleCollector" in job
    assert f"lr: {trials[1].params['algo.lr']!r}" in job and "epochs: 1\n" in job

    # 4) on demand: --summary, with the plots
    assert main(["sweep=smoke", f"sweep.root_dir={root}", "--summary"]) == 0
    assert {p.name for p in (study_dir / "plots").glob("*.png")} >= {
        "history.png",
        "parallel_coordinates.png",
        "intermediate_values.png",
    }


@pytest.mark.slow
def test_two_processes_share_one_study(tmp_path: Path) -> None:
    root = tmp_path / "sweeps"
    common = ["sweep=smoke", f"sweep.root_dir={root}", "sweep.n_trials=4", "sweep.plots=false",
              "experiment=smoke", "total_frames=512"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    procs = [
        subprocess.Popen([sys.executable, str(ROOT / "scripts" / "sweep.py"), *common, f"sweep.worker={w}"],
                         cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for w in (0, 1)
    ]
    try:
        assert [p.wait(timeout=600) for p in procs] == [0, 0]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    storage = optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(str(root / "smoke" / "journal.log"))
    )
    trials = optuna.load_study(study_name="smoke", storage=storage).get_trials()
    pids = {t.user_attrs["pid"] for t in trials}
    assert 4 <= len(trials) <= 5 and len(pids) == 2  # both worked; at most one overshoot
    assert len({tuple(sorted(t.params.items())) for t in trials}) == len(trials)
