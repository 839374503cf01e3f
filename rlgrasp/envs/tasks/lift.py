"""Lift: grasp the object and hold it at least ``success_height`` above where it rested."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from rlgrasp.envs.tasks.base import Task
from rlgrasp.envs.tasks.terms import grasp, reach, success


def lift(task: Any, readings: Mapping[str, Any]) -> float:
    """Progress of a held object towards ``success_height`` (0 unless grasped), in [0, 1]."""
    if readings["grasped"][0] <= 0.5:
        return 0.0
    return min(max(task.lift_height(readings) / task.success_height, 0.0), 1.0)


class LiftTask(Task):
    """Success = the object at least ``success_height`` above its own rest height, held by both fingers.

    ``dense`` (the default) pays reach + grasp + 2 x lift + success, divided by their weights' sum
    (at most 1 a step); ``sparse`` pays 1 on success. ``weights`` reweights the set's terms
    (``env.task.weights={lift: 4}``).
    """

    TERMS = {"reach": reach, "grasp": grasp, "lift": lift, "success": success}
    TERM_SETS = {
        "dense": {
            "terms": {
                "reach": {"weight": 1.0},
                "grasp": {"weight": 1.0},
                "lift": {"weight": 2.0},
                "success": {"weight": 1.0},
            },
            "normalize": True,
        },
        "sparse": {"terms": {"success": {"weight": 1.0}}, "normalize": True},
    }

    def __init__(self, scene: Any, objects: Any = "cube", success_height: float = 0.05, **task: Any):
        if not (
            isinstance(success_height, (int, float)) and math.isfinite(success_height) and success_height > 0
        ):
            raise ValueError(f"env.task.success_height must be a positive number, got {success_height!r}")
        self.success_height = float(success_height)
        super().__init__(scene, objects, **task)

    def lift_height(self, readings: Mapping[str, Any]) -> float:
        return readings["object_pos"][2] - self.rest_z

    def succeeded(self, readings: Mapping[str, Any]) -> bool:
        return bool(readings["grasped"][0] > 0.5 and self.lift_height(readings) >= self.success_height)
