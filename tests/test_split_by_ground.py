"""benchmarks/split_by_ground.py: the docs' per-look figures (plain / checker / rings) are read from an
evaluation's episodes.csv by ground, by object, or by the pair."""

from __future__ import annotations

import csv
import runpy
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def write_episodes(path: Path) -> Path:
    """Four episodes under ``visual=heldout`` (one texture, rings: index 0; -1 is a plain colour)."""
    rows = [  # object texture, ground texture, success
        (-1, -1, 1.0),
        (-1, 0, 0.0),
        (0, -1, 1.0),
        (0, 0, 1.0),
    ]
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        header = ["seed", "visual_object_texture", "visual_ground_texture", "success_at_end", "outcome"]
        writer.writerow(header)
        for seed, (obj, ground, success) in enumerate(rows):
            writer.writerow([seed, obj, ground, success, "success" if success else "never grasped"])
    return path


def test_split_by_ground_object_and_both(tmp_path):
    split = runpy.run_path(str(ROOT / "benchmarks" / "split_by_ground.py"))["split"]
    episodes = write_episodes(tmp_path / "episodes.csv")
    by_ground, outcomes = split(episodes, "heldout")
    assert by_ground == {"plain": [1.0, 1.0], "rings": [0.0, 1.0]}
    assert outcomes == {"plain": {"success": 2}, "rings": {"success": 1, "never grasped": 1}}
    assert split(episodes, "heldout", "object")[0] == {"plain": [1.0, 0.0], "rings": [1.0, 1.0]}
    both = split(episodes, "heldout", "both")[0]  # object / ground
    assert both == {
        "plain / plain": [1.0],
        "plain / rings": [0.0],
        "rings / plain": [1.0],
        "rings / rings": [1.0],
    }


def test_split_by_ground_reads_only_the_seeds_asked_for(tmp_path):
    script = runpy.run_path(str(ROOT / "benchmarks" / "split_by_ground.py"))
    episodes = write_episodes(tmp_path / "episodes.csv")
    by_ground, outcomes = script["split"](episodes, "heldout", seeds=script["seed_range"]("1-2"))
    assert by_ground == {"plain": [1.0], "rings": [0.0]}  # seeds 1 and 2 only
    assert script["describe"]("rings", [0.0, 1.0], outcomes["rings"]) == "rings 0.50 (2; never grasped 1)"
