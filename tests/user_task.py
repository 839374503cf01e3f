"""A user's own task and reward term, outside the package (docs/tasks.md shows the same): the tests
register them from here to prove that a new task or term needs no edit of rlgrasp."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlgrasp.envs.tasks import LiftTask


def hand_height(task: Any, readings: Mapping[str, Any], target: float = 0.2) -> float:
    """1 when the grasp point is at ``target`` metres, less below and above it."""
    return max(0.0, 1.0 - abs(float(readings["grasp_pos"][2]) - target) / target)


class HighLiftTask(LiftTask):
    """Lift, but only 15 cm counts, and the hand is paid for rising (``hand_height``)."""

    TERMS = {**LiftTask.TERMS, "hand_height": hand_height}
    TERM_SETS = {
        **LiftTask.TERM_SETS,
        "dense": {
            "terms": {**LiftTask.TERM_SETS["dense"]["terms"], "hand_height": {"weight": 0.5}},
            "normalize": True,
        },
    }

    def __init__(self, scene: Any, objects: Any = "cube", success_height: float = 0.15, **task: Any):
        super().__init__(scene, objects, success_height=success_height, **task)
