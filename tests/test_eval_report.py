"""Run comparison: per-run table, aggregate across seeds with bootstrap CIs, learning curves."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rlgrasp.evaluation.report import band, build_report, expand_runs, main, read_scalars
from rlgrasp.stats import iqm


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
