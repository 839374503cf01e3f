"""Learning benchmark: eval success against wall-clock minutes and env frames, several seeds.

Runs ``scripts/train.py experiment=<experiment>`` once per seed, one after the other (each run has
the whole machine), under a wall-clock budget, then reads each run's ``eval/success_rate`` from
TensorBoard and writes a CSV and a PNG. Minutes count from the launch of the training process, so
start-up time is charged to the run.

    python benchmarks/bench_learning.py --seeds 0 1 2 --minutes 5 --out outputs/bench_learning
    python benchmarks/bench_learning.py --minutes 30 --tag joint_delta -- env.control_mode=joint_delta
    python benchmarks/bench_learning.py --experiment grasp_objects_ppo --tag grasp_objects_ppo --minutes 20 \
        --eval-objects random_urdfs_test train_mix --eval-episodes 200

``--eval-objects`` evaluates each run's last checkpoint after training with ``scripts/evaluate.py``
on those object sets (config group ``objects``), e.g. the held-out ``random_urdfs_test``.
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
from rlgrasp.stats import wilson_interval
from rlgrasp.utils import pyplot

ROOT = Path(__file__).resolve().parents[1]


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
        sys.executable, str(ROOT / "scripts" / "evaluate.py"), f"ckpt={run_dir}", "ckpt_kind=last",
        f"objects={objects}", f"episodes={episodes}", "workers=2", "video=false", "tensorboard=false",
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--minutes", type=float, default=5.0)
    parser.add_argument("--experiment", default="grasp_ppo")
    parser.add_argument("--tag", default="grasp_ppo")
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_learning")
    parser.add_argument("--eval-objects", nargs="*", default=[], help="sets to evaluate after training")
    parser.add_argument("--eval-episodes", type=int, default=200)
    parser.add_argument("overrides", nargs="*", help="extra training overrides, after --")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    rows, finals, held_out = [], [], []
    for seed in args.seeds:
        run = run_seed(args.out, args.tag, seed, args.minutes, args.experiment, args.overrides)
        curve = eval_curve(run["run_dir"], run["start"])
        rows += [(args.tag, seed, round(m, 3), f, v) for m, f, v in curve]
        minutes, frames, success = curve[-1]
        first_90 = next(((m, f) for m, f, v in curve if v >= 0.9 - 1e-6), None)
        episodes = final_episodes(run["run_dir"])
        low, high = wilson_interval(round(success * episodes), episodes)
        finals.append((seed, minutes, frames, success, first_90, episodes, low, high))
        print(f"seed {seed}: final eval success {success:.3f} over {episodes} episodes "
              f"[{low:.3f}, {high:.3f}] at {frames:,} frames, {minutes:.1f} min; "
              f"first >= 0.9 at {first_reach(first_90)}", flush=True)
        for objects in args.eval_objects:
            r = evaluate_on(run["run_dir"], objects, args.eval_episodes)
            held_out.append((seed, objects, r))
            print(f"seed {seed}: last checkpoint on {objects}: {r['successes']}/{r['episodes']} "
                  f"= {r['rate']:.3f} [{r['ci95'][0]:.3f}, {r['ci95'][1]:.3f}]", flush=True)

    csv_path = args.out / f"{args.tag}.csv"
    with open(csv_path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["tag", "seed", "minutes", "frames", "eval_success_rate"])
        writer.writerows(rows)
    plot(rows, args.out / f"{args.tag}.png", args.tag)

    print(f"\n{args.tag}: budget {args.minutes} min per seed")
    print(f"{'seed':>4}{'final success':>15}{'episodes':>9}{'95% Wilson':>16}{'frames':>10}{'minutes':>9}"
          f"{'first >= 0.9':>26}")
    for seed, minutes, frames, success, first_90, episodes, low, high in finals:
        print(f"{seed:>4}{success:>15.3f}{episodes:>9}{f'[{low:.2f}, {high:.2f}]':>16}{frames:>10,}"
              f"{minutes:>9.1f}{first_reach(first_90):>26}")
    print(at_frames(rows))
    hits = sum(round(f[3] * f[5]) >= 0.9 * f[5] for f in finals)  # counts: 0.9 is 0.8999... in float32
    print(f"seeds with final eval success >= 0.9: {hits}/{len(finals)}")
    for seed, objects, r in held_out:
        print(f"seed {seed} on {objects:>20}: {r['rate']:.3f} over {r['episodes']} episodes "
              f"[{r['ci95'][0]:.2f}, {r['ci95'][1]:.2f}]")
    print(f"wrote {csv_path} and {csv_path.with_suffix('.png')}")


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
