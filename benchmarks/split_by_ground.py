"""Success of an evaluation split by the ground's look: how the docs' "plain / checker / rings"
figures are read from an evaluation's ``episodes.csv`` (``scripts/evaluate.py`` writes one per run).

    python benchmarks/split_by_ground.py --visual heldout \
        outputs/bench_learning/vision/<run>/eval/test_heldout/episodes.csv

The ground's texture is the ``visual_ground_texture`` column: -1 for a plain colour, else an index
into the visual preset's textures (``rlgrasp.envs.visuals.VISUAL_PRESETS``), so the preset the
evaluation ran with names them. ``--by object`` splits by the object's texture instead
(``visual_object_texture``), ``--by both`` by the pair, written ``object / ground``: whether it is
the object's look or the ground's that a policy misses. Each look also lists how its failures
ended (the ``outcome`` column). ``--seeds 0-99`` reads only those episodes' rows (the ``seed``
column), to set a 200-episode evaluation beside a 100-episode one on the same episodes.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled

from rlgrasp.envs.visuals import VISUAL_PRESETS


def split(
    path: Path, visual: str, by: str = "ground", seeds: range | None = None
) -> tuple[dict[str, list[float]], dict[str, Counter]]:
    """Each look's successes at the end (1.0 / 0.0), the look being the ground's texture, the
    object's, or both (``by``), and each look's outcomes; only the episodes of ``seeds`` if given."""
    textures = VISUAL_PRESETS[visual].textures
    surfaces = ("object", "ground") if by == "both" else (by,)
    by_look: dict[str, list[float]] = defaultdict(list)
    outcomes: dict[str, Counter] = defaultdict(Counter)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if seeds is not None and int(row["seed"]) not in seeds:
                continue
            indices = [int(float(row[f"visual_{surface}_texture"])) for surface in surfaces]
            look = " / ".join("plain" if i < 0 else textures[i] for i in indices)
            by_look[look].append(float(row["success_at_end"]))
            outcomes[look][row["outcome"]] += 1
    return by_look, outcomes


def seed_range(text: str) -> range:
    """``"0-99"`` as ``range(0, 100)``: the seeds' rows to read, both ends included."""
    first, _, last = text.partition("-")
    try:
        return range(int(first), int(last or first) + 1)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds {text!r}: expected FIRST-LAST, e.g. 0-99") from None


def describe(look: str, successes: list[float], outcomes: Counter) -> str:
    """``checker 0.68 (44; tipped or rolled 8, slipped 6)``: success, episodes and how the rest ended."""
    failures = ", ".join(f"{name} {n}" for name, n in outcomes.most_common() if name != "success")
    count = f"{len(successes)}; {failures}" if failures else f"{len(successes)}"
    return f"{look} {sum(successes) / len(successes):.2f} ({count})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("episodes", nargs="+", type=Path, help="episodes.csv files of evaluations")
    parser.add_argument("--visual", default="default", choices=sorted(VISUAL_PRESETS))
    parser.add_argument("--by", default="ground", choices=("ground", "object", "both"))
    parser.add_argument("--seeds", type=seed_range, default=None, help="FIRST-LAST: only these episodes")
    args = parser.parse_args()
    for path in args.episodes:
        by_look, outcomes = split(path, args.visual, args.by, args.seeds)
        n = sum(len(v) for v in by_look.values())
        if n == 0:
            sys.exit(f"{path}: no episode of seeds {args.seeds} in it")
        lifted = sum(sum(v) for v in by_look.values()) / n
        looks = ", ".join(describe(look, v, outcomes[look]) for look, v in sorted(by_look.items()))
        print(f"{path}: {lifted:.3f} of {n}; {looks}; {dict(sum(outcomes.values(), Counter()))}")


if __name__ == "__main__":
    main()
