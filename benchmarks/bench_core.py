"""The training core's own cost: a whole run from launch against raw env stepping and the collector.

    python benchmarks/bench_core.py [--rounds 2] [--seconds 20] [--variant NAME=OVERRIDES ...] \
        [-- hydra overrides of every run, default experiment=grasp_ppo_fast]

One sequential script, so that the ratios come from one stretch of the machine's time. Each round
measures, one after the other:

1. raw: one process per core, each stepping one env with random actions (``bench_collect.py``'s
   raw loop), the ceiling for this machine;
2. the collector alone with the actor (``bench_collect.py``'s), its workers already started;
3. each variant: ``scripts/train.py`` as a user launches it, timed from the launch of the process to
   its exit (start-up, periodic evaluations, checkpoints, the final evaluation, shutdown included),
   with the training log's last line (``Phases``: where the time went).

A variant is ``NAME=OVERRIDES`` (space-separated Hydra overrides over the common ones), e.g.
``--variant "in-learner=eval.background=false" --variant "shipped="``, or ``NAME@CHECKOUT=OVERRIDES``
to run another checkout's ``scripts/train.py`` (the commit before a change, from ``git worktree``);
default: the experiment as shipped. Variants alternate within each round. Prints each round, then
for each figure its minimum and median over the rounds and the ratios to raw of the medians.

``--record PAGE/ID`` writes the whole runs' median ratios to raw into that row of
docs/benchmarks/results.json and its page's table (benchmarks/results_file.py), met when the first
variant's ratio is >= ``--target``:

    python benchmarks/bench_core.py --rounds 2 --record throughput/end-to-end --target 0.75
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_file
from bench_collect import bench_collector, bench_raw

from rlgrasp.compose import compose_train
from rlgrasp.envs.factory import env_factory
from rlgrasp.train.tracking.metrics import parse_phases

ROOT = Path(__file__).resolve().parents[1]


def whole_run(overrides: list[str], root: Path = ROOT) -> dict[str, float]:
    """``scripts/train.py`` of the checkout ``root`` from launch to exit: frames/s, and the phases
    from its ``train.log``."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, str(root / "scripts" / "train.py"), *overrides, f"paths.output_dir={tmp}"]
        env = {**os.environ, "PYTHONPATH": str(root)}
        t0 = time.perf_counter()
        done = subprocess.run(cmd, cwd=root, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t0
        log = (Path(tmp) / "train.log").read_text() if (Path(tmp) / "train.log").exists() else ""
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd[1:])} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    finished = [line for line in log.splitlines() if "finished at" in line]
    frames = int(finished[-1].split("finished at ")[1].split(" frames")[0].replace(",", ""))
    phases = [line for line in log.splitlines() if "time from launch" in line]
    out = {"frames": frames, "wall_s": wall, "fps": frames / wall}
    out.update(parse_phases(phases[-1]) if phases else {})
    return out


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=20.0, help="raw and collector: seconds each")
    parser.add_argument("--procs", type=int, default=2, help="raw processes (the cores)")
    parser.add_argument("--variant", action="append", default=[], help="NAME=OVERRIDES (repeatable)")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides of every run")
    results_file.add_options(parser)
    parser.add_argument("--target", type=float, help="with --record: the first variant's ratio to raw")
    return parser.parse_args()


def main() -> None:
    args = parse_args()

    common = args.overrides or ["experiment=grasp_ppo_fast"]
    variants = {}
    for spec in args.variant or ["shipped="]:
        name, _, extra = spec.partition("=")
        name, _, root = name.partition("@")
        variants[name] = (extra.split(), Path(root) if root else ROOT)
    cfg = compose_train([*common, "paths.output_dir=/tmp/unused"])
    make_env = env_factory(cfg.env)
    print(f"common overrides: {common}; variants: {variants}", flush=True)

    figures: dict[str, list[float]] = {"raw": [], "collector": []}
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in variants}
    for r in range(args.rounds):
        raw = bench_raw(make_env, args.seconds, args.procs)
        figures["raw"].append(raw)
        print(f"round {r}: raw {raw:,.0f} frames/s", flush=True)
        col = bench_collector(cfg, args.seconds)
        figures["collector"].append(col)
        print(f"round {r}: collector {col:,.0f} frames/s ({col / raw:.2f} of raw)", flush=True)
        for name, (extra, root) in variants.items():
            run = whole_run([*common, *extra], root)
            runs[name].append(run)
            figures.setdefault(name, []).append(run["fps"])
            phases = ", ".join(f"{k} {v:.1f}" for k, v in run.items() if k not in ("frames", "wall_s", "fps"))
            print(
                f"round {r}: {name}: {run['frames']:,} frames in {run['wall_s']:.1f} s from launch, "
                f"{run['fps']:,.0f} frames/s ({run['fps'] / raw:.2f} of this round's raw); {phases}",
                flush=True,
            )

    raw_med = statistics.median(figures["raw"])
    print(f"\n{'':<28} {'min':>9} {'median':>9}  median/raw   ({args.rounds} rounds)")
    for name, values in figures.items():
        med = statistics.median(values)
        print(f"{name:<28} {min(values):9,.0f} {med:9,.0f}  {med / raw_med:.2f}")
    for name, rs in runs.items():
        keys = [k for k in rs[0] if k not in ("frames", "wall_s", "fps")]
        print(
            f"{name}: median seconds "
            + ", ".join(f"{k} {statistics.median(x.get(k, 0.0) for x in rs):.1f}" for k in keys)
        )
    if args.record:
        medians = {name: statistics.median(figures[name]) for name in variants}
        met = (
            "see page"
            if args.target is None
            else results_file.met_of([next(iter(medians.values())) / raw_med >= args.target])
        )
        results_file.record(
            *args.record, record_text(medians, raw_med, args.rounds), met, load=args.record_load
        )


def record_text(medians: dict[str, float], raw: float, rounds: int) -> str:
    """The results table's ``measured`` cell: each variant's whole run as a share of raw stepping
    (medians over the rounds), with the frames/s behind the ratio when there is one variant."""
    if len(medians) == 1:
        fps = next(iter(medians.values()))
        return f"{fps / raw:.2f} ({fps:,.0f} against {raw:,.0f} raw frames/s, medians of {rounds} rounds)"
    ratios = ", ".join(f"{name} {fps / raw:.2f}" for name, fps in medians.items())
    return f"{ratios} of raw ({raw:,.0f} frames/s, medians of {rounds} rounds)"


if __name__ == "__main__":
    main()
