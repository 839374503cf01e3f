"""Success of an evaluation split by the ground's look: how the docs' "plain / checker / rings"
figures are read from an evaluation's ``episodes.csv`` (``scripts/evaluate.py`` writes one per run).

    python benchmarks/split_by_ground.py --visual heldout \
        outputs/bench_learning/vision/<run>/eval/test_heldout/episodes.csv

The ground's texture is the ``visual_ground_texture`` column: -1 for a plain colour, else an index
into the visual preset's textures (``rlgrasp.envs.visuals.VISUAL_PRESETS``), so the preset the
evaluation ran with names them. ``--by object`` splits by the object's texture instead
(``visual_object_texture``), ``--by both`` by the pair, written ``object / ground``: whether it is
the object's look or the ground's that a policy misses.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled

from rlgrasp.envs.visuals import VISUAL_PRESETS


def split(path: Path, visual: str, by: str = "ground") -> tuple[dict[str, list[float]], Counter]:
    """Each look's successes at the end (1.0 / 0.0), the look being the ground's texture, the
    object's, or both (``by``), and every episode's outcome."""
    textures = VISUAL_PRESETS[visual].textures
    surfaces = ("object", "ground") if by == "both" else (by,)
    by_look: dict[str, list[float]] = defaultdict(list)
    outcomes: Counter = Counter()
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            indices = [int(float(row[f"visual_{surface}_texture"])) for surface in surfaces]
            look = " / ".join("plain" if i < 0 else textures[i] for i in indices)
            by_look[look].append(float(row["success_at_end"]))
            outcomes[row["outcome"]] += 1
    return by_look, outcomes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("episodes", nargs="+", type=Path, help="episodes.csv files of evaluations")
    parser.add_argument("--visual", default="default", choices=sorted(VISUAL_PRESETS))
    parser.add_argument("--by", default="ground", choices=("ground", "object", "both"))
    args = parser.parse_args()
    for path in args.episodes:
        by_ground, outcomes = split(path, args.visual, args.by)
        n = sum(len(v) for v in by_ground.values())
        lifted = sum(sum(v) for v in by_ground.values()) / n
        grounds = ", ".join(f"{g} {sum(v) / len(v):.2f} ({len(v)})" for g, v in sorted(by_ground.items()))
        print(f"{path}: {lifted:.3f} of {n}; {grounds}; {dict(outcomes)}")


if __name__ == "__main__":
    main()
