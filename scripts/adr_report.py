"""Policies side by side on `default`, on `wide` and on the ranges an ADR run reached (docs/adr.md).

    python scripts/adr_report.py <adr run> <default-trained run> [scripted] \
        [--ranges <adr run>/adr_ranges.yaml] [--episodes 100] [--workers 2] [--out DIR]

Each policy is a run directory (its last checkpoint), a checkpoint file, or ``scripted`` (the
expert, for scale). Not the best checkpoint: an ADR run's periodic evaluation plays its start
ranges (nominal values), so its "best" is the first policy to lift the cube there, often from
early in the run, before any range widened. ``--ranges`` defaults to the first run's
``adr_ranges.yaml``. Every policy meets the same seeded episodes per condition
(rlgrasp.evaluation). Prints a markdown table; with ``--out`` also writes it and
``adr_report.json`` there.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.envs.randomization import PARAMS, Randomizer  # noqa: E402
from rlgrasp.evaluation.episodes import timed_run  # noqa: E402
from rlgrasp.evaluation.metrics import summarize  # noqa: E402
from rlgrasp.evaluation.source import EvaluationError, prepare  # noqa: E402
from rlgrasp.train.collection.adr_sync import RANGES_FILE  # noqa: E402
from rlgrasp.utils import markdown_table  # noqa: E402


def _source(policy: str, randomization: str) -> Any:
    if policy in ("scripted", "random"):
        return prepare(policy, randomization=randomization)
    return prepare("checkpoint", policy, "last", randomization)


def _conditions(policies: list[str], ranges: str | None) -> dict[str, str]:
    """Condition label -> randomization: the two presets, and the ADR ranges when there are any."""
    if ranges is None:
        found = [Path(p) / RANGES_FILE for p in policies if (Path(p) / RANGES_FILE).is_file()]
        ranges = str(found[0]) if found else None
    elif not Path(ranges).is_file():
        raise EvaluationError(f"--ranges {ranges}: no such file")
    return {"default": "default", "wide": "wide", **({"adr ranges": ranges} if ranges else {})}


def compare(policies: list[str], ranges: str | None, episodes: int, seed: int, workers: int) -> dict:
    """Success at the end of the episode, with its 95% Wilson interval, per policy and condition."""
    conditions = _conditions(policies, ranges)
    for policy in policies:  # every input checked before the first episode runs
        for randomization in conditions.values():
            _source(policy, randomization)
    results: dict[str, dict[str, Any]] = {}
    for policy in policies:
        for label, randomization in conditions.items():
            found, _ = timed_run(
                source=_source(policy, randomization), episodes=episodes, base_seed=seed, workers=workers
            )
            results.setdefault(policy, {})[label] = summarize(found)["success_at_end"]
    report = {"conditions": conditions, "episodes": episodes, "seed": seed, "success": results}
    if "adr ranges" in conditions:
        report["contain_default"] = contain_default(conditions["adr ranges"])
    return report


def contain_default(ranges_file: str) -> list[str]:
    """The parameters (of all the randomizer's) whose range in the file contains `default`'s."""
    reached, default = Randomizer(ranges_file).ranges, Randomizer("default").ranges
    nominal = {name: (spec.nominal, spec.nominal) for name, spec in PARAMS.items()}

    def bounds(ranges: dict, name: str) -> tuple[float, float]:
        r = ranges.get(name)
        return (r.low, r.high) if r is not None else nominal[name]

    def contains(name: str) -> bool:
        (low, high), (d_low, d_high) = bounds(reached, name), bounds(default, name)
        return low <= d_low and d_high <= high

    return [name for name in PARAMS if contains(name)]


def table(report: dict) -> str:
    labels = list(report["conditions"])
    rows = [
        [policy] + [f"{r[c]['rate']:.2f} [{r[c]['ci95'][0]:.2f}, {r[c]['ci95'][1]:.2f}]" for c in labels]
        for policy, r in report["success"].items()
    ]
    return markdown_table(["policy", *labels], rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="run dirs, checkpoint files, or scripted")
    parser.add_argument("--ranges", help=f"an ADR ranges file (default: the first run's {RANGES_FILE})")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=100_000)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", help="a directory for adr_report.md and adr_report.json")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.workers < 1:
        print("error: --episodes and --workers must be >= 1", file=sys.stderr)
        return 2
    try:
        report = compare(args.policies, args.ranges, args.episodes, args.seed, args.workers)
    except (EvaluationError, ValueError) as exc:
        print(f"error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    text = table(report)
    if "contain_default" in report:
        text += f"\n\nADR ranges containing default's: {len(report['contain_default'])} of {len(PARAMS)}"
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "adr_report.md").write_text(text + "\n")
        (out / "adr_report.json").write_text(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
