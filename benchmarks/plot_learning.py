"""Learning curves of several variants side by side, from the CSVs ``bench_learning.py`` writes (or
``bench_peer.py``'s, one per seed: there each side is a variant).

    python benchmarks/plot_learning.py outputs/bench_learning/grasp_ppo.csv \
        outputs/bench_learning/grasp_ppo_fast.csv --out docs/img/grasp_ppo_vs_fast.png

Each variant (a CSV's ``tag``) is drawn as the mean eval success over its seeds with the band from
the lowest to the highest seed, against env frames (comparable across machines) and against
minutes from launch (only within one machine's session). Seeds are aligned on the frames of their
periodic evaluations; a run cut early by its budget stops counting where its last evaluation is.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.utils import pyplot


def read_curves(paths: list[Path]) -> dict[str, dict[int, list[tuple[float, int, float]]]]:
    """tag (bench_peer's: side) -> seed -> [(minutes, frames, success)], in the order of the evaluations."""
    curves: dict[str, dict[int, list[tuple[float, int, float]]]] = defaultdict(lambda: defaultdict(list))
    for path in paths:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                point = (float(row["minutes"]), int(row["frames"]), float(row["eval_success_rate"]))
                curves[row.get("tag") or row["side"]][int(row["seed"])].append(point)
    return curves


def band(seeds: dict[int, list[tuple[float, int, float]]], axis: int) -> tuple[list, list, list, list]:
    """x, mean, low, high over the seeds at the x values every seed has reached (axis 0: minutes,
    1: frames); minutes differ per seed, so there each seed's value is its last evaluation at or
    before x."""
    if axis == 1:
        xs = sorted(set.intersection(*({p[1] for p in pts} for pts in seeds.values())))
    else:  # from the time every seed has been evaluated once to the time the first seed stopped
        start = max(pts[0][0] for pts in seeds.values())
        stop = min(pts[-1][0] for pts in seeds.values())
        xs = sorted({p[0] for pts in seeds.values() for p in pts if start <= p[0] <= stop})
    mean, low, high = [], [], []
    for x in xs:
        values = [max((p for p in pts if p[axis] <= x), key=lambda p: p[axis])[2] for pts in seeds.values()]
        mean.append(sum(values) / len(values))
        low.append(min(values))
        high.append(max(values))
    return xs, mean, low, high


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("csvs", type=Path, nargs="+", help="bench_learning.py CSVs (any number of tags)")
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    parser.add_argument("--title", default="eval success: mean over seeds, band = lowest to highest seed")
    args = parser.parse_args()

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for tag, seeds in read_curves(args.csvs).items():
        for ax, axis in zip(axes, (1, 0)):
            xs, mean, low, high = band(seeds, axis)
            line = ax.plot(xs, mean, marker=".", label=f"{tag} ({len(seeds)} seeds)")[0]
            ax.fill_between(xs, low, high, color=line.get_color(), alpha=0.15)
    for ax, xlabel in zip(axes, ("env frames", "wall-clock minutes (from launch)")):
        ax.set_xlabel(xlabel)
        ax.set_ylabel("eval success rate")
        ax.set_ylim(-0.02, 1.02)
        ax.axhline(0.9, color="grey", lw=0.8, ls="--")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right")
    fig.suptitle(args.title)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
