"""Lift: the task owns the episode's object, measures it, and says what success and reward are.

Like panda-gym's ``Task``, it places its own bodies on reset (the object drawn from the object
sets, at the drawn pose and dynamics), so the env only resets the robot and then the task.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from rlgrasp.envs.objects import ObjectChoice, ObjectSampler, snap_scale, tilt
from rlgrasp.envs.scene import Scene

REWARD_KINDS = ("dense", "sparse")
NOMINAL_OBJECT_XY = (0.6, 0.0)  # below the grasp point at the neutral pose


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the dense reward's stages; the reward is divided by their sum (max 1 a step)."""

    reach: float = 1.0
    grasp: float = 1.0
    lift: float = 2.0
    success: float = 1.0

    @staticmethod
    def from_mapping(weights: Mapping[str, float] | None) -> RewardWeights:
        """Weights from a config mapping (None: the defaults); an unknown name fails naming it."""
        names = [f.name for f in fields(RewardWeights)]
        unknown = sorted(set(weights or {}) - set(names))
        if unknown:
            raise ValueError(
                f"unknown reward weight {unknown[0]!r} (env.reward_weights); weights: " + ", ".join(names)
            )
        return RewardWeights(**(weights or {}))

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
        scene: Scene,
        objects: Any = "cube",
        reward: str = "dense",
        weights: RewardWeights | dict | None = None,
        success_height: float = 0.05,
    ):
        if reward not in REWARD_KINDS:
            raise ValueError(f"unknown reward {reward!r}; valid rewards: {', '.join(REWARD_KINDS)}")
        self.scene, self.client = scene, scene.client
        self.objects = objects if isinstance(objects, ObjectSampler) else ObjectSampler(objects)
        self.reward_kind = reward
        self.weights = weights if isinstance(weights, RewardWeights) else RewardWeights(**(weights or {}))
        self.success_height = success_height
        self.object_name = ""
        self.object_extents = np.zeros(3, np.float32)
        self._offset = np.zeros(3)
        self._has_offset = False
        self.rest_z = 0.0
        self.settle_substeps = 0

    # --- the object ----------------------------------------------------------------------------
    def reset(self, choice: ObjectChoice, episode: dict[str, Any], randomized: set[str]) -> None:
        """Build the drawn object upright at the drawn pose with the drawn (or its own) dynamics.

        ``randomized``: the parameters the randomizer draws; mass and friction it leaves alone are the
        object's own. ``episode`` gains the values actually used (snapped scale, own mass).
        """
        scale = episode["object_size_scale"] = snap_scale(episode["object_size_scale"])
        geometry = self.objects.geometry(choice)
        self.object_name = f"cube/{scale:.1f}" if choice.name == "cube" else choice.name
        self.object_extents = np.array(geometry.extents, np.float32) * np.float32(scale)
        self._offset = np.array(geometry.offset) * scale
        self._has_offset = bool(self._offset.any())  # read every step: asked once an episode
        self.rest_z = geometry.rest_height * scale
        self.settle_substeps = 0
        xy = np.add(NOMINAL_OBJECT_XY, (episode["object_x"], episode["object_y"]))
        quat = self.client.getQuaternionFromEuler((0.0, 0.0, episode["object_yaw"]))
        body = self.scene.spawn(choice, scale, [xy[0], xy[1], self.rest_z], quat)
        if "object_mass" not in randomized:
            episode["object_mass"] = geometry.mass
        if "object_lateral_friction" not in randomized:
            episode["object_lateral_friction"] = geometry.lateral_friction
        self.client.changeDynamics(
            body,
            -1,
            mass=episode["object_mass"],
            lateralFriction=episode["object_lateral_friction"],
            spinningFriction=episode["object_spinning_friction"],
            rollingFriction=episode["object_rolling_friction"],
            restitution=episode["object_restitution"],
        )
        if choice.kind in ("mesh", "urdf") and choice.name != "cube":
            self._settle()

    def _settle(self, max_substeps: int = 48, speed: float = 5e-3) -> None:
        """Let a mesh come to rest and take its height then as its rest height.

        A mesh's bounding box says where its lowest point is, not whether it stands: many
        random_urdfs rock or tip onto a flatter side. Lifting is measured from where it settled.
        Those substeps simulate the robot too: reset the robot first.
        """
        c, body = self.client, self.scene.object
        for i in range(max_substeps):
            c.stepSimulation()
            if i >= 8:
                linear, angular = c.getBaseVelocity(body)
                if max(map(abs, linear)) < speed and max(map(abs, angular)) < 10 * speed:
                    break
        self.settle_substeps = i + 1
        self.rest_z = c.getBasePositionAndOrientation(body)[0][2]

    # --- measuring -----------------------------------------------------------------------------
    def grasped(self, robot_body: int, finger_links: list[int]) -> bool:
        """Both fingers touch the object."""
        body, contacts = self.scene.object, self.client.getContactPoints
        return all(contacts(bodyA=robot_body, bodyB=body, linkIndexA=link) for link in finger_links)

    def readings(self, grasp_pos: np.ndarray, robot_body: int, finger_links: list[int]) -> dict[str, Any]:
        """The object's state by observation part name (privileged: no robot senses it directly)."""
        c, body = self.client, self.scene.object
        object_pos, object_quat = c.getBasePositionAndOrientation(body)
        object_linvel, object_angvel = c.getBaseVelocity(body)
        object_pos = np.array(object_pos)
        centre = object_pos
        if self._has_offset:
            rotation = np.array(c.getMatrixFromQuaternion(object_quat)).reshape(3, 3)
            centre = object_pos + rotation @ self._offset
        grasped = self.grasped(robot_body, finger_links)
        return {
            "object_pos": object_pos,
            "object_quat": object_quat,
            "object_linvel": object_linvel,
            "object_angvel": object_angvel,
            "object_minus_grasp": centre - grasp_pos,
            "object_extents": self.object_extents,
            "grasped": np.array([float(grasped)]),
            "object_centre": centre,
        }

    def evaluate(self, readings: dict[str, Any], grasp_pos: np.ndarray) -> tuple[float, bool]:
        """Reward and success for one step; the reach term pulls towards the object's centre."""
        lift = readings["object_pos"][2] - self.rest_z
        grasped = bool(readings["grasped"][0])
        success = bool(grasped and lift >= self.success_height)
        if self.reward_kind == "sparse":
            return float(success), success
        w = self.weights
        offset = readings["object_centre"] - grasp_pos  # its norm as np.linalg.norm computes it
        reach = 1.0 - math.tanh(5.0 * math.sqrt(offset.dot(offset)))
        progress = min(max(lift / self.success_height, 0.0), 1.0) if grasped else 0.0
        total = w.reach * reach + w.grasp * grasped + w.lift * progress + w.success * success
        return total / (w.reach + w.grasp + w.lift + w.success), success

    def info(self, readings: dict[str, Any], success: bool) -> dict[str, Any]:
        """What changes every step."""
        # numpy scalars, not Python ones: TorchRL's info reader needs a dtype.
        return {
            "is_success": np.bool_(success),
            "grasped": np.bool_(readings["grasped"][0] > 0.5),
            "lift_height": np.float32(readings["object_pos"][2] - self.rest_z),
            "object_tilt": np.float32(tilt(readings["object_quat"])),
        }

    def episode_info(self) -> dict[str, Any]:
        """What the episode fixed when it began."""
        return {"object": self.object_name, "object_extents": self.object_extents.copy()}
