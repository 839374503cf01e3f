"""Learning benchmark: eval success against wall-clock minutes and env frames, several seeds.

Runs ``scripts/train.py experiment=<experiment>`` once per seed, one after the other (each run has
the whole machine), under a wall-clock budget, then reads each run's ``eval/success_rate`` from
TensorBoard and writes a CSV and a PNG. Minutes count from the launch of the training process, so
start-up time is charged to the run.

    python benchmarks/bench_learning.py --seeds 0 1 2 --minutes 5 --out outputs/bench_learning
    python benchmarks/bench_learning.py --minutes 30 --tag joint_delta -- env.control.mode=joint_delta
    python benchmarks/bench_learning.py --experiment grasp_objects_ppo --tag grasp_objects_ppo --minutes 20 \
        --eval-objects random_urdfs_test train_mix --eval-episodes 200

``--eval-objects`` evaluates each run's last checkpoint after training with ``scripts/evaluate.py``
on those object sets (config group ``objects``), e.g. the held-out ``random_urdfs_test``.

``--record PAGE/ID`` writes the run's figures into that row of docs/benchmarks/results.json and its
page's table (benchmarks/results_file.py): per seed the frames and minutes of the first evaluation
>= ``--record-threshold`` and the final success (and each ``--eval-objects`` set's), met when every
seed's final success (or ``--target-on``'s set) is >= ``--target`` and, with ``--target-frames``,
its first evaluation >= the threshold came within those frames:

    python benchmarks/bench_learning.py --experiment grasp_ppo_fast --seeds 0 1 2 --minutes 5 \
        --tag grasp_ppo_fast --record learning/fast-final-097 --target 0.97 --record-load alone
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

from omegaconf import OmegaConf
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_file, also when loaded by path
import results_file

from rlgrasp.stats import wilson_interval
from rlgrasp.utils import pyplot

ROOT = Path(__file__).resolve().parents[1]
SUCCESS = "eval_success_rate"  # the CSV's column of each evaluation's success


def run_seed(out: Path, tag: str, seed: int, minutes: float, experiment: str, overrides: list[str]) -> dict:
    run_dir = out / f"{tag}_seed{seed}"
    cmd = [
        sys.executable,
        str(ROOT / "scripts" / "train.py"),
        f"experiment={experiment}",
        f"seed={seed}",
        f"time_budget_min={minutes}",
        f"hydra.run.dir={run_dir}",
        *overrides,
    ]
    print("$", " ".join(cmd[1:]), flush=True)
    start = time.time()
    with open(out / f"{tag}_seed{seed}.log", "w") as log:
        code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
    if code != 0:
        raise SystemExit(f"training run for seed {seed} failed (exit {code}); see {log.name}")
    return {"run_dir": run_dir, "start": start, "wall_s": time.time() - start}


def evaluate_on(run_dir: Path, objects: str, episodes: int) -> dict:
    """success_at_end of the run's last checkpoint on ``objects`` (seeds 0..episodes-1)."""
    name = f"bench_{objects}"
    cmd = [
        sys.executable,
        str(ROOT / "scripts" / "evaluate.py"),
        f"ckpt={run_dir}",
        "ckpt_kind=last",
        f"objects={objects}",
        f"episodes={episodes}",
        "workers=2",
        "video=false",
        "tensorboard=false",
        f"name={name}",
    ]
    print("$", " ".join(cmd[1:]), flush=True)
    with open(run_dir / f"{name}.log", "w") as log:
        if subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT) != 0:
            raise SystemExit(f"evaluation of {run_dir} on {objects} failed; see {log.name}")
    return json.loads((run_dir / "eval" / name / "metrics.json").read_text())["success_at_end"]


def final_episodes(run_dir: Path) -> int:
    """Episodes behind a run's last eval point: the final evaluation's count."""
    cfg = OmegaConf.load(run_dir / ".hydra" / "config.yaml").eval
    return int(cfg.get("final_episodes") or cfg.episodes)


def scalar_curve(run_dir: Path, start: float, tag: str) -> list[tuple[float, int, float]]:
    """(minutes since launch, frames, value) of every point of a run's TensorBoard scalar ``tag``."""
    acc = EventAccumulator(str(run_dir / "tensorboard"), size_guidance={"scalars": 0})
    acc.Reload()
    return [((e.wall_time - start) / 60, e.step, e.value) for e in acc.Scalars(tag)]


def eval_curve(run_dir: Path, start: float) -> list[tuple[float, int, float]]:
    """(minutes since launch, frames, eval success) for every periodic evaluation."""
    return scalar_curve(run_dir, start, "eval/success_rate")


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--minutes", type=float, default=5.0)
    parser.add_argument("--experiment", default="grasp_ppo")
    parser.add_argument("--tag", default="grasp_ppo")
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_learning")
    parser.add_argument("--eval-objects", nargs="*", default=[], help="sets to evaluate after training")
    parser.add_argument("--eval-episodes", type=int, default=200)
    parser.add_argument("overrides", nargs="*", help="extra training overrides, after --")
    results_file.add_options(parser)
    parser.add_argument(
        "--record-threshold",
        type=float,
        default=0.9,
        help="with --record: the success of the 'first evaluation >=' figure",
    )
    parser.add_argument("--target", type=float, help="with --record: the final success each seed must reach")
    parser.add_argument(
        "--target-on",
        default="final",
        help="with --target: 'final' (training's final evaluation) or an --eval-objects set",
    )
    parser.add_argument(
        "--target-frames",
        type=int,
        help="with --record: the frames within which the first evaluation >= the threshold",
    )
    args = parser.parse_args()
    if args.target_on != "final" and args.target_on not in args.eval_objects:
        parser.error(f"--target-on {args.target_on}: not 'final' nor one of --eval-objects")
    return args


def main() -> None:
    args = parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    rows, finals, held_out, curves = [], [], [], {}
    for seed in args.seeds:
        run = run_seed(args.out, args.tag, seed, args.minutes, args.experiment, args.overrides)
        curve = curves[seed] = eval_curve(run["run_dir"], run["start"])
        rows += [(args.tag, seed, round(m, 3), f, v) for m, f, v in curve]
        minutes, frames, success = curve[-1]
        first_90 = next(((m, f) for m, f, v in curve if v >= 0.9 - 1e-6), None)
        episodes = final_episodes(run["run_dir"])
        low, high = wilson_interval(round(success * episodes), episodes)
        finals.append((seed, minutes, frames, success, first_90, episodes, low, high))
        print(
            f"seed {seed}: final eval success {success:.3f} over {episodes} episodes "
            f"[{low:.3f}, {high:.3f}] at {frames:,} frames, {minutes:.1f} min; "
            f"first >= 0.9 at {first_reach(first_90)}",
            flush=True,
        )
        for objects in args.eval_objects:
            r = evaluate_on(run["run_dir"], objects, args.eval_episodes)
            held_out.append((seed, objects, r))
            print(
                f"seed {seed}: last checkpoint on {objects}: {r['successes']}/{r['episodes']} "
                f"= {r['rate']:.3f} [{r['ci95'][0]:.3f}, {r['ci95'][1]:.3f}]",
                flush=True,
            )

    csv_path = args.out / f"{args.tag}.csv"
    rows = write_curves(csv_path, rows, args.seeds)
    plot(rows, args.out / f"{args.tag}.png", args.tag)

    print(f"\n{args.tag}: budget {args.minutes} min per seed")
    print(
        f"{'seed':>4}{'final success':>15}{'episodes':>9}{'95% Wilson':>16}{'frames':>10}{'minutes':>9}"
        f"{'first >= 0.9':>26}"
    )
    for seed, minutes, frames, success, first_90, episodes, low, high in finals:
        print(
            f"{seed:>4}{success:>15.3f}{episodes:>9}{f'[{low:.2f}, {high:.2f}]':>16}{frames:>10,}"
            f"{minutes:>9.1f}{first_reach(first_90):>26}"
        )
    print(at_frames(rows))
    hits = sum(round(f[3] * f[5]) >= 0.9 * f[5] for f in finals)  # counts: 0.9 is 0.8999... in float32
    print(f"seeds with final eval success >= 0.9: {hits}/{len(finals)}")
    for seed, objects, r in held_out:
        print(
            f"seed {seed} on {objects:>20}: {r['rate']:.3f} over {r['episodes']} episodes "
            f"[{r['ci95'][0]:.2f}, {r['ci95'][1]:.2f}]"
        )
    print(f"wrote {csv_path} and {csv_path.with_suffix('.png')}")
    if args.record:
        met = record_met(
            curves, held_out, args.record_threshold, args.target, args.target_on, args.target_frames
        )
        results_file.record(
            *args.record, record_text(curves, held_out, args.record_threshold), met, load=args.record_load
        )


Curve = list[tuple[float, int, float]]  # (minutes from launch, frames, eval success)


def write_curves(csv_path: Path, rows: list[tuple], seeds: list[int]) -> list[tuple]:
    """Write ``rows`` to ``csv_path`` after the rows it holds of other seeds, and return them all:
    a tag run again on another seed adds its curve instead of erasing the earlier seeds'."""
    kept = []
    if csv_path.is_file():
        with open(csv_path, newline="") as f:
            kept = [
                (r["tag"], int(r["seed"]), float(r["minutes"]), int(r["frames"]), float(r[SUCCESS]))
                for r in csv.DictReader(f)
                if int(r["seed"]) not in seeds
            ]
    rows = [*kept, *rows]
    with open(csv_path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["tag", "seed", "minutes", "frames", SUCCESS])
        writer.writerows(rows)
    return rows


def first_at(curve: Curve, threshold: float) -> tuple[float, int] | None:
    """(minutes, frames) of the first evaluation >= ``threshold`` (0.9 is 0.8999... in float32)."""
    return next(((m, f) for m, f, v in curve if v >= threshold - 1e-6), None)


def record_text(curves: dict[int, Curve], held_out: list[tuple[int, str, dict]], threshold: float) -> str:
    """The results table's ``measured`` cell for these seeds: the frames and minutes of the first
    evaluation >= ``threshold``, the final success, each evaluated object set's rate; one value per
    seed, in the seeds' order, as the pages write them."""
    seeds = sorted(curves)
    firsts = [first_at(curves[s], threshold) for s in seeds]
    frames = " / ".join("-" if p is None else f"{round(p[1] / 1000)}k" for p in firsts)
    minutes = " / ".join("-" if p is None else f"{p[0]:.1f}" for p in firsts)
    text = f"first >= {threshold:g} at {frames} frames ({minutes} min); final "
    text += " / ".join(f"{curves[s][-1][2]:.2f}" for s in seeds)
    for objects in dict.fromkeys(o for _, o, _ in held_out):
        rates = {seed: r["rate"] for seed, o, r in held_out if o == objects}
        text += f"; {objects} " + " / ".join(f"{rates[s]:.3f}" for s in seeds if s in rates)
    return text + f" (seeds {' / '.join(map(str, seeds))})"


def record_met(
    curves: dict[int, Curve],
    held_out: list[tuple[int, str, dict]],
    threshold: float,
    target: float | None,
    target_on: str = "final",
    target_frames: int | None = None,
) -> str:
    """The ``met`` cell: per seed, the final success (or ``target_on``'s object set) >= ``target``
    and the first evaluation >= ``threshold`` within ``target_frames``; "see page" without either."""
    if target is None and target_frames is None:
        return "see page"
    rates = {seed: r["rate"] for seed, o, r in held_out if o == target_on}
    flags = []
    for seed in sorted(curves):
        ok = True
        if target is not None:
            value = curves[seed][-1][2] if target_on == "final" else rates.get(seed, float("nan"))
            ok = value >= target - 1e-6
        if target_frames is not None:
            first = first_at(curves[seed], threshold)
            ok = ok and first is not None and first[1] <= target_frames
        flags.append(ok)
    return results_file.met_of(flags)


def first_reach(point: tuple[float, int] | None) -> str:
    return "-" if point is None else f"{point[0]:.1f} min, {point[1]:,} frames"


def at_frames(rows: list[tuple], marks: tuple[int, ...] = (40960, 81920, 122880, 163840, 204800)) -> str:
    """Mean periodic eval success over the seeds at fixed frame counts: the per-frame comparison
    that does not depend on the machine's speed (the eval at the first point at or after each mark)."""
    parts = []
    for mark in marks:
        values = []
        for seed in sorted({r[1] for r in rows}):
            later = [r[4] for r in rows if r[1] == seed and r[3] >= mark]
            if later:
                values.append(later[0])
        if values:
            parts.append(f"{mark // 1024}k: {sum(values) / len(values):.2f} ({len(values)} seeds)")
    return "mean eval success at " + "; ".join(parts)


def plot(rows: list[tuple], path: Path, title: str) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for seed in sorted({r[1] for r in rows}):
        pts = [r for r in rows if r[1] == seed]
        axes[0].plot([r[2] for r in pts], [r[4] for r in pts], marker=".", label=f"seed {seed}")
        axes[1].plot([r[3] for r in pts], [r[4] for r in pts], marker=".", label=f"seed {seed}")
    for ax, xlabel in zip(axes, ("wall-clock minutes (from launch)", "env frames")):
        ax.set_xlabel(xlabel)
        ax.set_ylabel("eval success rate")
        ax.set_ylim(-0.02, 1.02)
        ax.axhline(0.9, color="grey", lw=0.8, ls="--")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    main()
