"""Compare runs: ``rlgrasp-report <run dirs or globs> [--out DIR]`` (or ``python scripts/report.py``).

For each run: its final evaluation, from ``rlgrasp-eval`` (the newest ``eval/*/metrics.json``, or
``--eval NAME``), else the one training ran at its end (``training_evaluation``); the tables say
which. For each group of runs that differ only by seed (same ``experiment_name``, or ``--group-by
none``): the mean and the interquartile mean of the final success rate with stratified-bootstrap 95%
intervals, as rliable reports them. Learning curves (success rate and return against env frames) come from
the runs' TensorBoard logs: the mean across seeds with a bootstrap 95% band, as a PNG.
"""

from __future__ import annotations

import argparse
import csv
import glob
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from rlgrasp.policy_file import CheckpointError, read_checkpoint
from rlgrasp.received import ReceivedError, check_tree
from rlgrasp.rundir import CHECKPOINTS
from rlgrasp.stats import iqm, stratified_bootstrap_ci, wilson_interval
from rlgrasp.utils import markdown_table, pyplot

SUCCESS_TAGS = ("eval/success_rate", "charts/success_rate")
#: Where a run's final evaluation comes from (the reports say which).
FROM_EVAL, FROM_TRAINING = "rlgrasp-eval", "training"
RETURN_TAGS = ("charts/episodic_return", "eval/mean_reward")


@dataclass
class RunRecord:
    """One training run: where it is, what it was, its final evaluation and its curves."""

    path: Path
    experiment: str
    seed: Any
    evaluation: dict[str, Any] | None
    eval_dir: Path | None
    source: str | None = None  # FROM_EVAL or FROM_TRAINING (None: no evaluation)
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)


def is_run_dir(path: Path) -> bool:
    return path.is_dir() and ((path / "checkpoints").is_dir() or (path / "tensorboard").is_dir())


def expand_runs(patterns: Sequence[str]) -> list[Path]:
    """Run directories from paths or globs; a folder of runs (``outputs/train/smoke``) expands too."""
    found: list[Path] = []
    for pattern in patterns:
        matches = [Path(p) for p in sorted(glob.glob(pattern))] or [Path(pattern)]
        for m in matches:
            if is_run_dir(m):
                found.append(m)
            elif m.is_dir():
                for child in sorted(m.iterdir()):  # a folder of runs someone sent: no link followed
                    if child.is_symlink():
                        raise ReceivedError(
                            f"{m}: refused: {child.name} is a symlink; runs are read where they lie"
                        )
                    found += [child] if is_run_dir(child) else []
    unique = list(dict.fromkeys(p.resolve() for p in found))
    if not unique:
        raise FileNotFoundError(
            f"no run directories (with checkpoints/ or tensorboard/) match {list(patterns)}"
        )
    return unique


def final_evaluation(run: Path, name: str | None = None) -> tuple[dict[str, Any] | None, Path | None]:
    """The named evaluation, or the newest one by file time."""
    if name:
        path = run / "eval" / name / "metrics.json"
        return (json.loads(path.read_text()), path.parent) if path.is_file() else (None, None)
    files = sorted((run / "eval").glob("*/metrics.json"), key=lambda p: p.stat().st_mtime)
    return (json.loads(files[-1].read_text()), files[-1].parent) if files else (None, None)


def training_evaluation(run: Path) -> dict[str, Any] | None:
    """The evaluation training ran at its end, in the shape of an ``rlgrasp-eval`` ``metrics.json``:
    ``last.pt``'s ``last_eval`` when it evaluated that checkpoint's weights (its success over its
    episodes, with a Wilson interval; no ``success_once``). None for a run without one (stopped
    midway, or an env without success)."""
    try:
        ckpt = read_checkpoint(run / CHECKPOINTS / "last.pt")
    except CheckpointError:
        return None
    last, cfg = ckpt.get("last_eval") or {}, ckpt["config"]
    if last.get("frames") != ckpt.get("frames") or "success_rate" not in last:
        return None
    periodic = cfg.get("eval") or {}
    # Runs from before ``last_eval`` kept its episode count ended with eval.final_episodes.
    episodes = int(last.get("episodes") or periodic.get("final_episodes") or periodic.get("episodes"))
    rate = float(last["success_rate"])
    wins = round(rate * episodes)
    return {
        "episodes": episodes,
        "success_at_end": {
            "rate": rate,
            "successes": wins,
            "episodes": episodes,
            "ci95": list(wilson_interval(wins, episodes)),
        },
        "success_once": None,
        "return": {"mean": float(last["mean_reward"])},
        "checkpoint": {"path": str(run / CHECKPOINTS / "last.pt"), "frames": ckpt["frames"]},
        "config": {"train": {"experiment_name": cfg.get("experiment_name"), "seed": cfg.get("seed")}},
    }


def _run_identity(run: Path, evaluation: dict[str, Any] | None) -> tuple[str, Any]:
    """experiment_name and seed: from the evaluation, else the run's saved Hydra config, read as plain
    YAML: nothing of a received file is resolved (an ``${oc.env:...}`` would print the environment)."""
    train = ((evaluation or {}).get("config") or {}).get("train")
    if train:
        return str(train.get("experiment_name", run.parent.name)), train.get("seed")
    hydra_cfg = run / ".hydra" / "config.yaml"
    if hydra_cfg.is_file():
        try:
            cfg = yaml.safe_load(hydra_cfg.read_text())
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
            raise ReceivedError(f"{hydra_cfg}: unreadable YAML ({type(exc).__name__})") from None
        cfg = cfg if isinstance(cfg, dict) else {}
        seed = cfg.get("seed")
        return str(cfg.get("experiment_name", run.parent.name)), seed if isinstance(seed, int) else None
    return run.parent.name, None


def read_scalars(log_dir: Path, tags: Sequence[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``tag -> (steps, values)`` from every events file in ``log_dir`` (a resumed run's files
    included; a step logged twice keeps its last value)."""
    if not log_dir.is_dir():
        return {}
    acc = EventAccumulator(str(log_dir), size_guidance={"scalars": 0})
    acc.Reload()
    available = set(acc.Tags().get("scalars", []))
    out = {}
    for tag in tags:
        if tag in available:
            by_step = {e.step: e.value for e in acc.Scalars(tag)}
            steps = np.array(sorted(by_step), dtype=float)
            out[tag] = (steps, np.array([by_step[s] for s in sorted(by_step)], dtype=float))
    return out


def load_runs(patterns: Sequence[str], eval_name: str | None = None) -> list[RunRecord]:
    """Each run with its final evaluation: ``rlgrasp-eval``'s if it has one, else training's own
    (not when ``eval_name`` asks for a named one: that compares like with like)."""
    records = []
    for run in expand_runs(patterns):
        check_tree(run, f"run {run}")  # read where it lies: no link leads a read out of it
        evaluation, eval_dir = final_evaluation(run, eval_name)
        source = FROM_EVAL if evaluation else None
        if evaluation is None and eval_name is None:
            evaluation = training_evaluation(run)
            source = FROM_TRAINING if evaluation else None
        experiment, seed = _run_identity(run, evaluation)
        curves = read_scalars(run / "tensorboard", SUCCESS_TAGS + RETURN_TAGS)
        records.append(RunRecord(run, experiment, seed, evaluation, eval_dir, source, curves))
    return records


def aggregate(values: Sequence[float], reps: int = 2000, seed: int = 0) -> dict[str, Any]:
    """Mean and IQM across runs with stratified-bootstrap 95% intervals."""
    x = np.asarray(values, float)
    mean = stratified_bootstrap_ci(x, np.mean, reps=reps, seed=seed)
    inter = stratified_bootstrap_ci(x, iqm, reps=reps, seed=seed)
    return {
        "runs": int(x.size),
        "mean": mean[0],
        "mean_ci95": [mean[1], mean[2]],
        "iqm": inter[0],
        "iqm_ci95": [inter[1], inter[2]],
    }


def group_runs(records: Sequence[RunRecord], by: str) -> dict[str, list[RunRecord]]:
    groups: dict[str, list[RunRecord]] = {}
    for r in records:
        groups.setdefault(r.experiment if by == "experiment" else "all", []).append(r)
    return groups


def band(
    curves: Sequence[tuple[np.ndarray, np.ndarray]], points: int = 100, reps: int = 1000
) -> dict[str, np.ndarray]:
    """Mean across runs on a common frame grid, with a bootstrap 95% band (none for one run).

    The grid stops at the shortest run's last frame so that every point averages every seed.
    """
    curves = [(s, v) for s, v in curves if len(s)]
    end = min(s[-1] for s, _ in curves)
    start = max(s[0] for s, _ in curves)
    grid = np.linspace(start, end, points) if end > start else np.array([end])
    ys = np.stack([np.interp(grid, s, v) for s, v in curves])  # [runs, points]
    mean = ys.mean(0)
    if len(curves) < 2:
        return {"x": grid, "mean": mean, "low": mean, "high": mean}
    rng = np.random.default_rng(0)
    boot = ys[rng.integers(0, len(curves), size=(reps, len(curves)))].mean(1)  # [reps, points]
    low, high = np.percentile(boot, [2.5, 97.5], axis=0)
    return {"x": grid, "mean": mean, "low": low, "high": high}


def plot_learning_curves(groups: dict[str, list[RunRecord]], path: Path) -> Path | None:
    """Success rate and return against env frames, one line (and band) per group."""
    plt = pyplot()
    panels = (("success rate", SUCCESS_TAGS), ("episodic return", RETURN_TAGS))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    drawn = 0
    for ax, (label, tags) in zip(axes, panels):
        for name, runs in groups.items():
            # The first tag (eval/ before charts/) that some run of the group logged; the runs
            # without it (crashed early, another env) are left out and the legend counts the rest.
            tag = next((t for t in tags if any(len(r.curves.get(t, ((),))[0]) for r in runs)), None)
            if tag is None:
                continue
            have = [r.curves[tag] for r in runs if tag in r.curves and len(r.curves[tag][0])]
            b = band(have)
            n = len(have)
            line = ax.plot(b["x"], b["mean"], label=f"{name} ({n} run{'s' * (n > 1)}, {tag})")
            ax.fill_between(b["x"], b["low"], b["high"], color=line[0].get_color(), alpha=0.25)
            drawn += 1
        ax.set_xlabel("env frames")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7)
    fig.suptitle("mean across seeds, band: bootstrap 95% interval of the mean", fontsize=9)
    fig.tight_layout()
    if drawn:
        fig.savefig(path, dpi=110)
    plt.close(fig)
    return path if drawn else None


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.1%}"


def _source(r: RunRecord) -> str:
    """Where a run's numbers come from, as the tables say it."""
    return f"{FROM_EVAL} {r.eval_dir.name}" if r.source == FROM_EVAL else "training's final eval"


def _sources(runs: Sequence[RunRecord]) -> str:
    counts = {s: sum(r.source == s for r in runs) for s in (FROM_EVAL, FROM_TRAINING)}
    return ", ".join(f"{s} {n}" for s, n in counts.items() if n)


def runs_table(records: Sequence[RunRecord], root: Path | None = None) -> tuple[list[str], list[list[str]]]:
    head = [
        "run",
        "experiment",
        "seed",
        "frames",
        "source",
        "episodes",
        "success at end [95% Wilson]",
        "success once",
        "return mean",
    ]
    rows = []
    for r in records:
        e = r.evaluation
        name = str(r.path.relative_to(root)) if root and r.path.is_relative_to(root) else str(r.path)
        if e is None:
            rows.append([name, r.experiment, str(r.seed), "", "(no final evaluation)", "", "", "", ""])
            continue
        s = e["success_at_end"]
        frames = (e.get("checkpoint") or {}).get("frames")
        rows.append(
            [
                name,
                r.experiment,
                str(r.seed),
                "" if frames is None else f"{frames:,}",
                _source(r),
                str(e["episodes"]),
                f"{_pct(s['rate'])} [{_pct(s['ci95'][0])}, {_pct(s['ci95'][1])}]",
                _pct((e["success_once"] or {}).get("rate")),
                f"{e['return']['mean']:.2f}",
            ]
        )
    return head, rows


def aggregate_table(agg: dict[str, dict[str, Any]]) -> tuple[list[str], list[list[str]]]:
    head = [
        "group",
        "runs",
        "success mean [95% CI]",
        "success IQM [95% CI]",
        "return mean [95% CI]",
        "source",
    ]
    rows = []
    for name, a in agg.items():
        s, ret = a["success_at_end"], a["return_mean"]
        rows.append(
            [
                name,
                str(s["runs"]),
                f"{_pct(s['mean'])} [{_pct(s['mean_ci95'][0])}, {_pct(s['mean_ci95'][1])}]",
                f"{_pct(s['iqm'])} [{_pct(s['iqm_ci95'][0])}, {_pct(s['iqm_ci95'][1])}]",
                f"{ret['mean']:.2f} [{ret['mean_ci95'][0]:.2f}, {ret['mean_ci95'][1]:.2f}]",
                a["sources"],
            ]
        )
    return head, rows


def build_report(
    patterns: Sequence[str],
    out: Path,
    eval_name: str | None = None,
    group_by: str = "experiment",
    reps: int = 2000,
) -> dict[str, Any]:
    """Write ``report.md``, ``runs.csv``, ``aggregate.json`` and ``learning_curves.png`` into ``out``."""
    records = load_runs(patterns, eval_name)
    groups = group_runs(records, group_by)
    root = Path.cwd()
    head, rows = runs_table(records, root)
    agg = {}
    for name, runs in groups.items():
        evaluated = [r for r in runs if r.evaluation]
        if not evaluated:
            continue
        agg[name] = {
            "success_at_end": aggregate([r.evaluation["success_at_end"]["rate"] for r in evaluated], reps),
            "return_mean": aggregate([r.evaluation["return"]["mean"] for r in evaluated], reps),
            "runs": [str(r.path) for r in evaluated],
            "sources": _sources(evaluated),
        }
    agg_head, agg_rows = aggregate_table(agg)
    out.mkdir(parents=True, exist_ok=True)
    curves = plot_learning_curves(groups, out / "learning_curves.png")
    with open(out / "runs.csv", "w", newline="") as f:
        csv.writer(f).writerows([head, *rows])
    (out / "aggregate.json").write_text(json.dumps(agg, indent=2) + "\n")
    text = (
        f"# Run comparison\n\n## Runs (final evaluation)\n\n{markdown_table(head, rows)}\n\n"
        f"## Aggregate across seeds (stratified bootstrap, {reps} resamples)\n\n"
        + (
            markdown_table(agg_head, agg_rows)
            if agg_rows
            else "(no run has a final evaluation yet: let training finish, or run rlgrasp-eval)"
        )
        + (
            "\n\n![learning curves](learning_curves.png)\n"
            if curves
            else "\n\n(no TensorBoard curves found)\n"
        )
    )
    (out / "report.md").write_text(text)
    return {"records": records, "aggregate": agg, "text": text, "learning_curves": curves, "out": out}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="rlgrasp-report", description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories, folders of runs, or globs (quote them)")
    parser.add_argument("--out", type=Path, default=None, help="default: outputs/report/<timestamp>")
    parser.add_argument(
        "--eval", dest="eval_name", default=None, help="evaluation name (default: the newest)"
    )
    parser.add_argument("--group-by", choices=("experiment", "none"), default="experiment")
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap resamples")
    args = parser.parse_args(argv)
    if args.reps < 1:  # before any run is read or anything written: the bootstrap needs a resample
        print(f"error: --reps {args.reps}: must be at least 1 (bootstrap resamples)", file=sys.stderr)
        return 2
    out = args.out or Path("outputs/report") / datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    try:
        result = build_report(args.runs, out, args.eval_name, args.group_by, args.reps)
    except (FileNotFoundError, ReceivedError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(result["text"])
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
