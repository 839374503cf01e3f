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
from types import SimpleNamespace

import optuna
import pytest
from omegaconf import OmegaConf

from rlgrasp.algos.ppo.learner import PPOLearner
from rlgrasp.algos.ppo.schema import PPOConfig
from rlgrasp.compose import compose_train
from rlgrasp.config import SweepObjective
from rlgrasp.sweep.cli import is_sweep_override, main
from rlgrasp.sweep.objective import Interrupted, Objective, schedule_overrides
from rlgrasp.sweep.runner import compose, run_sweep
from rlgrasp.sweep.score import RunScore
from rlgrasp.sweep.space import parse_space, to_overrides
from rlgrasp.sweep.study import ATTR_INTERRUPTED, ATTR_RETRY_OF
from rlgrasp.utils import flatten

ROOT = Path(__file__).resolve().parents[1]


def test_space_parses_nested_params_and_names_bad_keys() -> None:
    space = parse_space(
        {
            "algo": {"optim": {"lr": {"type": "float", "low": 1e-4, "high": 1e-3, "log": True}}},
            "model": {"hidden_sizes": {"type": "categorical", "choices": [[64, 64], [128]]}},
            "collector": {"envs_per_worker": {"type": "int", "low": 2, "high": 8, "step": 2}},
        }
    )
    assert set(space.dists) == {"algo.optim.lr", "model.hidden_sizes", "collector.envs_per_worker"}
    assert space.dists["model.hidden_sizes"].choices == ("[64,64]", "[128]")
    assert to_overrides({"algo.optim.lr": 0.1, "a.b": None, "c": True}) == [
        "algo.optim.lr=0.1",
        "a.b=null",
        "c=true",
    ]
    with pytest.raises(ValueError, match="algo.optim.lr: type float needs 'high'"):
        parse_space({"algo": {"optim": {"lr": {"type": "float", "low": 1.0}}}})
    with pytest.raises(ValueError, match="algo.optim.lr"):
        parse_space({"algo": {"optim": {"lr": {"type": "gauss"}}}})
    assert is_sweep_override("sweep.n_trials=3") and is_sweep_override("+sweep.x=1")
    assert not is_sweep_override("sweeper=1") and not is_sweep_override("algo.optim.lr=1")


def _wait_for(path: Path, text: str, proc: subprocess.Popen, timeout: float = 240) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.is_file() and text in path.read_text():
            return
        assert proc.poll() is None, "the sweep ended before it could be interrupted"
        time.sleep(0.2)
    raise TimeoutError(f"{text!r} never appeared in {path}")


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_sweep_fails_prunes_resumes_and_summarizes(tmp_path: Path) -> None:
    root = tmp_path / "sweeps"
    sweep = [
        "sweep=smoke",
        f"sweep.root_dir={root}",
        "sweep.n_trials=3",
        "sweep.plots=false",
        # trial 0 crashes (unknown control mode), trial 1 runs as sampled
        "sweep.enqueue=[{env:{control:{mode:bogus}}},{algo:{optim:{epochs:1}}}]",
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
    result = run_sweep([*sweep, "sweep.pruner.name=threshold", "+sweep.pruner.kwargs.lower=1.0e9"], train)
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
        [
            sys.executable,
            str(ROOT / "scripts" / "train.py"),
            "--config-dir",
            str(best.parents[1]),
            "experiment=smoke_best",
            "--cfg",
            "job",
        ],
        capture_output=True,
        text=True,
        check=True,
        cwd=tmp_path,
    ).stdout
    assert "experiment_name: smoke_best" in job and "collectors.SingleCollector" in job
    assert f"lr: {trials[1].params['algo.optim.lr']!r}" in job and "epochs: 1\n" in job

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
    common = [
        "sweep=smoke",
        f"sweep.root_dir={root}",
        "sweep.n_trials=4",
        "sweep.plots=false",
        "experiment=smoke",
        "total_frames=512",
    ]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    procs = [
        subprocess.Popen(
            [sys.executable, str(ROOT / "scripts" / "sweep.py"), *common, f"sweep.worker={w}"],
            cwd=tmp_path,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
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


# --- objectives, several seeds per trial -------------------------------------------------------
BUDGET = 163_840


def _score(evals: list[tuple[int, float]], kind: str = "first_reach", budget: int = BUDGET) -> RunScore:
    score = RunScore(SweepObjective(kind=kind, threshold=0.9, tie_break=0.01), "success_rate", budget)
    for frames, success in evals:
        score.add(frames, {"success_rate": success, "mean_reward": 1.0})
    return score


def test_first_reach_ranks_reached_runs_by_frames_then_final_success() -> None:
    reached = _score([(20480, 0.5), (40960, 0.92), (61440, 0.8), (BUDGET, 0.95)])
    assert reached.reached_at == 40960
    assert reached.value() == pytest.approx(40960 * (1 - 0.01 * 0.95))
    never = _score([(20480, 0.3), (40960, 0.6), (BUDGET, 0.7)])
    assert never.reached_at is None and never.value() == pytest.approx(BUDGET * 1.3)
    # 0.9 of 30 episodes is 0.8999... in float32: it counts
    assert _score([(20480, 0.8999999), (BUDGET, 0.9)]).reached_at == 20480
    # the tie-break: the same first eval, the better final success wins ...
    same_eval_worse_end = _score([(40960, 0.9), (BUDGET, 0.91)])
    assert reached.value() < same_eval_worse_end.value() < 40960
    # ... but never over an earlier first eval, nor over a run that did not reach 0.9
    earlier = _score([(20480, 0.9), (BUDGET, 0.0)])
    last_minute = _score([(20480, 0.2), (BUDGET, 0.9)])  # the final evaluation counts too
    almost = _score([(20480, 0.2), (BUDGET, 0.89)])
    assert earlier.value() < reached.value() < last_minute.value() < BUDGET < almost.value() < never.value()
    # the final objective: the last evaluation's metric
    assert _score([(20480, 0.5), (BUDGET, 0.7)], kind="final").value() == pytest.approx(0.7)


def _run_trial(study: optuna.Study, evals: list[tuple[int, float]]) -> bool:
    """Report ``evals`` as a sweep's first seed does; True if the pruner stopped the trial."""
    trial, score = study.ask(), RunScore(SweepObjective(kind="first_reach"), "success_rate", BUDGET)
    for frames, success in evals:
        trial.report(score.add(frames, {"success_rate": success}), step=frames)
        if frames < BUDGET and trial.should_prune():
            study.tell(trial, state=optuna.trial.TrialState.PRUNED)
            return True
    study.tell(trial, score.value())
    return False


def test_median_pruner_compares_first_reach_reports_like_with_like() -> None:
    """The reports are projections onto the trial's budget: a slow learner is pruned at once. (A
    projection onto the frames so far would make a trial's first report its best: never pruned.)"""
    study = optuna.create_study(
        direction="minimize", pruner=optuna.pruners.MedianPruner(n_startup_trials=3, n_warmup_steps=0)
    )
    steps = (20480, 40960, 61440, BUDGET)
    for curve in ((0.4, 0.9, 0.95, 0.97), (0.3, 0.6, 0.9, 0.95), (0.2, 0.6, 0.7, 0.8)):
        assert not _run_trial(study, list(zip(steps, curve)))
    assert not _run_trial(study, list(zip(steps, (0.9, 0.95, 0.9, 0.97))))  # the best so far
    assert _run_trial(study, list(zip(steps, (0.1, 0.2, 0.3, 0.4))))
    assert study.trials[-1].last_step == 20480


def test_bad_objective_keys_are_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "sweeps"
    cases = {
        "sweep.objective.kind=fastest": (2, "objective.kind=fastest: must be one of final, first_reach"),
        "sweep.objective.treshold=0.8": (1, "treshold"),
        "sweep.objective.threshold=90": (2, "sweep.objective.threshold=90.0: must be in (0, 1]"),
        "sweep.direction=maximize": (2, "sweep.direction=maximize: objective.kind=first_reach counts frames"),
        "sweep.metric=mean_reward": (2, "sweep.metric=mean_reward: objective.kind=first_reach compares"),
        "sweep.trial.seeds=[0,0]": (2, "sweep.trial.seeds=[0, 0]: must not repeat a seed"),
        "sweep.trial.lr_schedule=run": (2, "sweep.trial.lr_schedule=run: must be one of trial, experiment"),
    }
    for override, (code, message) in cases.items():
        argv = ["sweep=grasp_ppo_speed", f"sweep.root_dir={root}", override, "experiment=smoke"]
        assert main(argv) == code, override
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert not root.exists()


def test_named_choice_sets_several_keys_and_the_lr_schedule_can_stay_the_experiments() -> None:
    space = parse_space(
        {
            "control": {
                "type": "categorical",
                "choices": {
                    "joint_delta": {"env": {"control": {"mode": "joint_delta", "ee_yaw": False}}},
                    "ee_delta_yaw": {"env": {"control": {"mode": "ee_delta", "ee_yaw": True}}},
                },
            },
            "algo": {"optim": {"epochs": {"type": "int", "low": 1, "high": 3}}},
        }
    )
    assert space.dists["control"].choices == ("joint_delta", "ee_delta_yaw") and "control" in space
    assert space.overrides({"control": "ee_delta_yaw", "algo.optim.epochs": 2}) == [
        "env.control.mode=ee_delta",
        "env.control.ee_yaw=true",
        "algo.optim.epochs=2",
    ]
    with pytest.raises(ValueError, match="control='ee': must be one of joint_delta, ee_delta_yaw"):
        space.overrides({"control": "ee"})
    with pytest.raises(ValueError, match="sweep.params.control.choices.a: must map training keys"):
        parse_space({"control": {"type": "categorical", "choices": {"a": 1}}})
    # a trial on 163,840 frames anneals as grasp_ppo's run does, over its 270,336
    cfg, configs = compose(["sweep=grasp_ppo_speed"], ROOT / "configs"), ROOT / "configs"
    assert schedule_overrides(cfg, ["experiment=grasp_ppo"], configs) == [
        "algo.schedule.anneal_lr_frames=270336"
    ]
    algo = OmegaConf.merge(
        OmegaConf.structured(PPOConfig), {"optim": {"lr": 1.0}, "schedule": {"anneal_lr_frames": 200}}
    )
    learner = SimpleNamespace(cfg=algo)
    assert PPOLearner.lr_at(learner, 50, 100) == pytest.approx(0.75)  # not 0.5: over 200 frames
    algo.schedule.anneal_lr_frames = None
    assert PPOLearner.lr_at(learner, 50, 100) == pytest.approx(0.5)


@pytest.mark.slow
def test_several_seeds_per_trial_mean_and_first_seed_pruning(tmp_path: Path) -> None:
    root = tmp_path / "sweeps"
    sweep = [
        "sweep=smoke",
        f"sweep.root_dir={root}",
        "sweep.plots=false",
        "sweep.pruner.name=none",
        "sweep.metric=success_rate",
        "sweep.direction=null",
        "sweep.objective.kind=first_reach",
        "sweep.trial.seeds=[3,4]",
        "sweep.trial.lr_schedule=experiment",
    ]
    # 1) one trial, two seeds: its value is their mean, each is kept and shown
    result = run_sweep([*sweep, "sweep.n_trials=1"], ["experiment=smoke"])
    study_dir = root / "smoke"
    storage = optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(str(study_dir / "journal.log"))
    )
    study = optuna.load_study(study_name="smoke", storage=storage)
    assert study.direction == optuna.study.StudyDirection.MINIMIZE
    (trial,) = study.get_trials()
    runs = trial.user_attrs["runs"]
    assert [r["seed"] for r in runs] == [3, 4] and trial.state.name == "COMPLETE"
    values = [r["value"] for r in runs]
    assert trial.value == pytest.approx(sum(values) / 2)
    for r in runs:  # smoke learns nothing in 1,024 frames: never 0.9, scored 1,024 x (2 - final)
        assert r["reached_at"] is None and r["value"] == pytest.approx(1024 * (2 - r["success_rate"]))
    assert {p.name for p in (study_dir / "trials" / "0000").iterdir()} == {"seed_3", "seed_4"}
    assert "algo.schedule.anneal_lr_frames=2048" in trial.user_attrs["overrides"]  # smoke's total_frames
    assert not any(o.startswith("seed=") for o in trial.user_attrs["overrides"])
    with (study_dir / "trials.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert [float(row["value_seed3"]), float(row["value_seed4"])] == pytest.approx(values)
    assert "Mean over the runs with seeds [3, 4]" in (study_dir / "trials.md").read_text()
    assert result["best_value"] == pytest.approx(trial.value)
    assert "anneal_lr_frames" not in result["best_config"].read_text()  # the experiment's own schedule

    # 2) the pruner sees the first seed; pruned, the trial ends there (the second seed never runs)
    run_sweep(
        [*sweep, "sweep.n_trials=2", "sweep.pruner.name=threshold", "+sweep.pruner.kwargs.upper=1000"],
        ["experiment=smoke"],
    )
    pruned = optuna.load_study(study_name="smoke", storage=storage).get_trials()[1]
    assert pruned.state.name == "PRUNED" and pruned.last_step == 512
    assert pruned.intermediate_values[512] > 1000 and "runs" not in pruned.user_attrs
    assert {p.name for p in (study_dir / "trials" / "0001").iterdir()} == {"seed_3"}


def test_the_refine_sweep_starts_from_grasp_ppo_fast_on_every_searched_key() -> None:
    cfg = compose(["sweep=grasp_ppo_refine"], ROOT / "configs")
    space = parse_space(OmegaConf.to_container(cfg.params))
    (first,) = cfg.enqueue
    trial0 = flatten(OmegaConf.to_container(first))
    fast = compose_train(["experiment=grasp_ppo_fast", "paths.output_dir=/tmp/unused"])
    assert set(trial0) == set(space.dists)  # every searched key is pinned, nothing else
    for key, value in trial0.items():
        assert OmegaConf.select(fast, key) == value, key
    assert not set(cfg.trial.seeds) & {0, 1, 2}  # the benchmark's seeds judge, they do not choose


class _Trial:
    """What an objective reads and writes of an Optuna trial."""

    number = 7

    def __init__(self) -> None:
        self.user_attrs: dict = {}

    def set_user_attr(self, key: str, value) -> None:
        self.user_attrs[key] = value


def test_a_signal_between_two_runs_still_marks_the_trial_interrupted(monkeypatch) -> None:
    """Ctrl-C after a run returned (between seeds, or after the last) reaches the objective, not the
    training loop: the trial must still be marked interrupted, or a resumed sweep would not retry it."""

    def signalled(self, trial):
        raise KeyboardInterrupt

    monkeypatch.setattr(Objective, "_trial", signalled)
    trial = _Trial()
    with pytest.raises(Interrupted, match="during trial 7"):
        Objective.__call__(object.__new__(Objective), trial)
    assert trial.user_attrs[ATTR_INTERRUPTED] is True
