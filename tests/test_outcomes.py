"""Failure reasons and success per object: the held-out evaluation's breakdown."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from rlgrasp.compose import compose_eval
from rlgrasp.evaluation.cli import evaluate
from rlgrasp.evaluation.outcomes import failure_reason, object_group, success_by_object

NARROW = (0.04, 0.06, 0.05)


@pytest.mark.parametrize(
    ("held", "tilts", "extents", "reason"),
    [
        ([False] * 4, [0.0] * 4, (0.09, 0.10, 0.05), "too wide"),
        ([False, False, True, True], [0.3, 0.3, 0.3 + math.radians(40), 0.3], NARROW, "tipped or rolled"),
        ([False, True, True, True], [0.5, 0.5, 0.5, 0.5 + math.radians(60)], NARROW, "held, not lifted"),
        ([False] * 4, [0.6] * 4, NARROW, "never grasped"),  # resting tilted is not tipping
        ([False, True, True, False], [0.0] * 4, NARROW, "slipped"),
    ],
)
def test_failure_reason(held, tilts, extents, reason) -> None:
    assert failure_reason(held, tilts, extents) == reason


def test_success_by_object_worst_first_with_intervals() -> None:
    objects = ["a/1", "a/1", "b/2", "b/2", "b/2", "primitives/box"]
    outcomes = ["success", "slipped", "success", "success", "success", "never grasped"]
    rows = success_by_object(objects, outcomes)
    assert [r["object"] for r in rows] == ["primitives/box", "a/1", "b/2"]
    assert rows[1]["successes"] == 1 and rows[1]["episodes"] == 2 and rows[1]["main_failure"] == "slipped"
    assert rows[2]["rate"] == 1.0 and rows[2]["main_failure"] == ""
    assert all(r["ci95"][0] <= r["rate"] <= r["ci95"][1] for r in rows)
    assert [object_group(r["object"]) for r in rows] == ["primitives/box", "a", "b"]


def test_evaluation_on_an_object_set_names_every_object(tmp_path: Path) -> None:
    """`objects=primitives` reaches the env; every episode names its object and gets one outcome."""
    cfg = compose_eval(
        [
            "policy=scripted",
            "objects=primitives",
            "episodes=6",
            "video=false",
            f"outputs_root={tmp_path}",
            "name=p",
        ]
    )
    m = evaluate(cfg)
    out = Path(m["output_dir"])
    assert m["config"]["env"]["objects"] == "primitives"
    assert sum(m["outcomes"].values()) == 6
    assert m["outcomes"].get("success", 0) == m["success_at_end"]["successes"]
    rows = list(csv.DictReader(open(out / "episodes.csv")))
    assert all(r["object"].startswith("primitives/") for r in rows)
    per_object = list(csv.DictReader(open(out / "objects.csv")))
    assert sum(int(r["episodes"]) for r in per_object) == 6
    assert (out / "success_by_object.png").is_file()
    assert "Success per object" in (out / "summary.md").read_text()
