"""Run comparison: per-run table, aggregate across seeds with bootstrap CIs, learning curves."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from rlgrasp.evaluation.report import band, build_report, expand_runs, main, read_scalars, training_evaluation
from rlgrasp.policy_file import load_checkpoint
from rlgrasp.stats import iqm, wilson_interval
from rlgrasp.train.checkpoint import save_checkpoint
from rlgrasp.train.loop import train
from tests.helpers import make_run


def fake_run(root: Path, name: str, seed: int, final: float, experiment: str = "exp") -> Path:
    """A run directory with TensorBoard curves and one evaluation, as training + rlgrasp-eval leave it."""
    from torch.utils.tensorboard import SummaryWriter

    run = root / name
    (run / "checkpoints").mkdir(parents=True)
    writer = SummaryWriter(str(run / "tensorboard"))
    for i, frames in enumerate(range(0, 5000, 1000)):
        writer.add_scalar("eval/success_rate", final * i / 4, frames)
        writer.add_scalar("charts/episodic_return", 10 * final * i / 4, frames)
    writer.close()
    ev = run / "eval" / "final"
    ev.mkdir(parents=True)
    metrics = {
        "episodes": 100,
        "success_at_end": {"rate": final, "successes": int(final * 100), "episodes": 100, "ci95": [0, 1]},
        "success_once": {"rate": final},
        "return": {"mean": 10 * final, "std": 1.0},
        "checkpoint": {"frames": 4000},
        "config": {"train": {"experiment_name": experiment, "seed": seed}},
    }
    (ev / "metrics.json").write_text(json.dumps(metrics))
    return run


def test_report_aggregates_seeds_and_draws_curves(tmp_path: Path) -> None:
    finals = [0.6, 0.8, 0.9, 0.7]
    for s, f in enumerate(finals):
        fake_run(tmp_path / "runs", f"seed{s}", s, f)
    fake_run(tmp_path / "runs", "other", 0, 0.1, experiment="other")
    out = tmp_path / "report"
    result = build_report([str(tmp_path / "runs" / "*")], out, reps=500)
    agg = result["aggregate"]
    assert set(agg) == {"exp", "other"}
    s = agg["exp"]["success_at_end"]
    assert (
        s["runs"] == 4
        and s["mean"] == pytest.approx(np.mean(finals))
        and s["iqm"] == pytest.approx(iqm(finals))
    )
    assert s["mean_ci95"][0] <= s["mean"] <= s["mean_ci95"][1]
    assert 0.6 <= s["mean_ci95"][0] and s["mean_ci95"][1] <= 0.9
    assert agg["other"]["success_at_end"]["mean_ci95"] == [0.1, 0.1]  # one run: no spread
    for f in ("report.md", "runs.csv", "aggregate.json", "learning_curves.png"):
        assert (out / f).is_file(), f
    assert (
        "seed2" in (out / "report.md").read_text() and len((out / "runs.csv").read_text().splitlines()) == 6
    )


def test_read_scalars_and_band(tmp_path: Path) -> None:
    run = fake_run(tmp_path, "r", 0, 0.8)
    curves = read_scalars(run / "tensorboard", ["eval/success_rate", "missing/tag"])
    steps, values = curves["eval/success_rate"]
    assert list(curves) == ["eval/success_rate"]
    assert steps.tolist() == [0, 1000, 2000, 3000, 4000] and values[-1] == pytest.approx(0.8)
    b = band([(steps, values), (steps[:4], values[:4] * 0.5)], points=4)
    assert b["x"][-1] == 3000  # only where every run has data
    assert np.all(b["low"] <= b["mean"] + 1e-12) and np.all(b["mean"] <= b["high"] + 1e-12)


def test_report_cli_errors_and_folder_expansion(tmp_path: Path, capsys) -> None:
    assert main([str(tmp_path / "nothing*")]) == 2
    assert "no run directories" in capsys.readouterr().err
    fake_run(tmp_path / "exp", "a", 0, 0.5)
    assert [p.name for p in expand_runs([str(tmp_path / "exp")])] == ["a"]  # a folder of runs
    assert main([str(tmp_path / "exp"), "--out", str(tmp_path / "rep"), "--reps", "100"]) == 0
    assert "Aggregate across seeds" in capsys.readouterr().out


#: A real training run in seconds: 16 frames in the learner's process, then a 3-episode final evaluation.
TINY = (
    "collector=single",
    "collector.envs_per_worker=1",
    "collector.steps_per_env=16",
    "algo.optim.minibatch_size=16",
    "total_frames=16",
    "eval.episodes=1",
    "eval.final_episodes=3",
    "eval.num_envs=3",
    "experiment_name=tiny",
    "seed=5",
)


def test_report_takes_trainings_final_evaluation_unless_rlgrasp_eval_has_one(tmp_path: Path, train_cfg):
    runs = tmp_path / "runs"
    train(train_cfg(*TINY, run_dir=runs / "trained"))
    last_eval = load_checkpoint(runs / "trained")["last_eval"]
    assert last_eval["frames"] == 16 and last_eval["episodes"] == 3
    shutil.copytree(runs / "trained", runs / "evaluated")  # the same run, then also through rlgrasp-eval
    ev = fake_run(tmp_path / "fake", "r", 6, 0.5, experiment="tiny") / "eval" / "final"
    shutil.copytree(ev, runs / "evaluated" / "eval" / "final")
    stopped = make_run(tmp_path / "stopped")  # checkpoints, no final evaluation

    result = build_report([str(runs / "*"), str(stopped)], tmp_path / "report", reps=100)
    by_name = {r.path.name: r for r in result["records"]}
    trained = by_name["trained"]
    sources = (trained.source, by_name["evaluated"].source, by_name["run"].source)
    assert sources == ("training", "rlgrasp-eval", None)
    wins = round(last_eval["success_rate"] * 3)
    assert trained.evaluation["success_at_end"] == {
        "rate": last_eval["success_rate"],
        "successes": wins,
        "episodes": 3,
        "ci95": list(wilson_interval(wins, 3)),
    }
    assert (trained.experiment, trained.seed) == ("tiny", 5)
    assert result["aggregate"]["tiny"]["success_at_end"]["runs"] == 2 and "unit" not in result["aggregate"]
    assert result["aggregate"]["tiny"]["sources"] == "rlgrasp-eval 1, training 1"
    text = result["text"]
    assert all(s in text for s in ("training's final eval", "rlgrasp-eval final", "(no final evaluation)"))

    named = build_report([str(runs / "*")], tmp_path / "named", eval_name="final", reps=100)
    assert named["aggregate"]["tiny"]["sources"] == "rlgrasp-eval 1"  # a named evaluation: no fallback
    alone = build_report([str(stopped)], tmp_path / "alone", reps=100)
    assert "no run has a final evaluation yet" in alone["text"]


def test_a_run_from_before_last_eval_kept_its_episodes_counts_the_final_episodes(tmp_path: Path) -> None:
    run = make_run(tmp_path)  # eval.final_episodes=100 in its config
    ckpt = load_checkpoint(run)
    ckpt["last_eval"] = {"mean_reward": 2.0, "success_rate": 0.87, "frames": ckpt["frames"]}
    save_checkpoint(run / "checkpoints" / "last.pt", ckpt)
    evaluation = training_evaluation(run)
    assert evaluation["episodes"] == 100 and evaluation["success_at_end"]["successes"] == 87
    ckpt["last_eval"]["frames"] -= 1  # a periodic evaluation of earlier weights: not the run's result
    save_checkpoint(run / "checkpoints" / "last.pt", ckpt)
    assert training_evaluation(run) is None
