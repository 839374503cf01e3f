"""Learning curves of several variants side by side, from the CSVs ``bench_learning.py`` writes (or
``bench_peer.py``'s, one per seed: there each side is a variant).

    python benchmarks/plot_learning.py outputs/bench_learning/grasp_ppo.csv \
        outputs/bench_learning/grasp_ppo_fast.csv --out docs/img/grasp_ppo_vs_fast.png

Each variant (a CSV's ``tag``) is drawn as ``rlgrasp-report`` draws a group of runs
(``rlgrasp.evaluation.report.band``: the mean over the seeds on a common grid that stops at the
shortest seed, with a bootstrap 95% band), against env frames (comparable across machines) and
against minutes from launch (only within one machine's session). The CSVs serve where the report's
TensorBoard runs do not exist (the SB3 side of ``bench_peer.py``) or the minutes matter.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
import numpy as np

from rlgrasp.evaluation.report import band
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


def along(seeds: dict[int, list[tuple[float, int, float]]], axis: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each seed's (x, success) arrays, x = minutes (axis 0) or frames (axis 1), for ``report.band``."""
    return [
        (np.array([p[axis] for p in pts], float), np.array([p[2] for p in pts], float))
        for pts in seeds.values()
    ]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("csvs", type=Path, nargs="+", help="bench_learning.py CSVs (any number of tags)")
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    parser.add_argument(
        "--title", default=("eval success: mean over seeds, band: bootstrap 95% interval of the mean")
    )
    args = parser.parse_args()

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for tag, seeds in read_curves(args.csvs).items():
        for ax, axis in zip(axes, (1, 0)):
            b = band(along(seeds, axis))
            runs = f"{len(seeds)} seed" + ("s" if len(seeds) != 1 else "")
            line = ax.plot(b["x"], b["mean"], label=f"{tag} ({runs})")[0]
            ax.fill_between(b["x"], b["low"], b["high"], color=line.get_color(), alpha=0.2)
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
