"""Lift: grasp detection, success and the staged reward."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pybullet_utils.bullet_client import BulletClient

REWARD_KINDS = ("dense", "sparse")


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the dense reward's stages; the reward is divided by their sum (max 1 a step)."""

    reach: float = 1.0
    grasp: float = 1.0
    lift: float = 2.0
    success: float = 1.0

    def __post_init__(self):
        for name in ("reach", "grasp", "lift", "success"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"reward weight {name!r} must be finite and >= 0, got {value}")
        if self.reach + self.grasp + self.lift + self.success <= 0:
            raise ValueError("reward weights must not all be zero")


class LiftTask:
    """Success = the object at least ``success_height`` above its own rest height, held by both fingers."""

    def __init__(
        self,
        reward: str = "dense",
        weights: RewardWeights | dict | None = None,
        success_height: float = 0.05,
    ):
        if reward not in REWARD_KINDS:
            raise ValueError(f"unknown reward {reward!r}; valid rewards: {', '.join(REWARD_KINDS)}")
        self.reward_kind = reward
        self.weights = weights if isinstance(weights, RewardWeights) else RewardWeights(**(weights or {}))
        self.success_height = success_height

    @staticmethod
    def grasped(client: BulletClient, robot_body: int, finger_links: list[int], body: int) -> bool:
        """Both fingers touch the object."""
        return all(
            client.getContactPoints(bodyA=robot_body, bodyB=body, linkIndexA=link)
            for link in finger_links
        )

    def evaluate(
        self, grasp_pos: np.ndarray, object_pos: np.ndarray, lift: float, grasped: bool
    ) -> tuple[float, bool]:
        """Reward and success for one step; ``object_pos`` is the point the reach term pulls towards."""
        success = bool(grasped and lift >= self.success_height)
        if self.reward_kind == "sparse":
            return float(success), success
        w = self.weights
        reach = 1.0 - math.tanh(5.0 * float(np.linalg.norm(object_pos - grasp_pos)))
        progress = min(max(lift / self.success_height, 0.0), 1.0) if grasped else 0.0
        total = w.reach * reach + w.grasp * grasped + w.lift * progress + w.success * success
        return total / (w.reach + w.grasp + w.lift + w.success), success
