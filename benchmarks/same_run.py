"""Is a refactor's run the same run? Train one config in an earlier commit and in this checkout and
compare every TensorBoard scalar, value for value.

The earlier commit is checked out into a temporary git worktree and run from there (its own code on
``PYTHONPATH``), then this checkout; both on this machine, one after the other. Wall-clock tags
(``time/*``, ``charts/SPS``) are left out, and so are tags only one side writes (listed). Exit 1
when a shared tag differs.

    python benchmarks/same_run.py --before e08ad73 -- experiment=smoke
    python benchmarks/same_run.py --before e08ad73 -- experiment=grasp_sac total_frames=5120
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

ROOT = Path(__file__).resolve().parents[1]
WALL_CLOCK = ("time/", "charts/SPS", "hparam/")


def scalars(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar of every event file under ``run_dir`` (the hparams file included), by tag."""
    out: dict[str, list[tuple[int, float]]] = {}
    for events in sorted(run_dir.rglob("events.out.tfevents.*")):
        acc = EventAccumulator(str(events), size_guidance={"scalars": 0})
        acc.Reload()
        for tag in acc.Tags()["scalars"]:
            if not tag.startswith(WALL_CLOCK):
                out[tag] = [(e.step, e.value) for e in acc.Scalars(tag)]
    return out


def train(tree: Path, run_dir: Path, overrides: list[str]) -> dict[str, list[tuple[int, float]]]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    command = [sys.executable, "scripts/train.py", *overrides, f"paths.output_dir={run_dir}"]
    subprocess.run(command, cwd=tree, env=env, check=True, capture_output=True)
    return scalars(run_dir)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="the earlier commit (any git ref)")
    parser.add_argument("overrides", nargs="*", help="training overrides, after --")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run(["git", "worktree", "add", "--detach", str(tmp / "before"), args.before], cwd=ROOT,
                       check=True, capture_output=True)  # fmt: skip
        try:
            before = train(tmp / "before", tmp / "run_before", args.overrides)
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(tmp / "before")], cwd=ROOT, check=False
            )
        after = train(ROOT, tmp / "run_after", args.overrides)
    shared = sorted(set(before) & set(after))
    differ = [tag for tag in shared if before[tag] != after[tag]]
    print(f"{len(shared)} shared tags, {len(shared) - len(differ)} identical value for value")
    for tag in differ:
        print(f"  differs: {tag}: before {before[tag][:3]} ... after {after[tag][:3]} ...")
    for side, only in (("before", set(before) - set(after)), ("after", set(after) - set(before))):
        if only:
            print(f"  only {side}: {', '.join(sorted(only))}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
