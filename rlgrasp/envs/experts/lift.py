"""The lift expert: a scripted grasp that acts only through ``ee_delta`` actions and the observation.

It proves the task solvable for each object set and randomization preset and is the baseline a
learned policy is compared with. It grasps top-down across the object's narrowest horizontal
extent; with ``ee_yaw`` (action_dim 5) it turns the hand to that direction, without it the hand
keeps yaw 0. Where the grasp point goes on the object is the gripper's: an arm's description may
set ``expert: {finger_reach, floor_clearance, hover}`` (``ScriptedExpert.for_env`` reads it).

Its grasp phases (approach, descend, close) are the goal experts' first phases too
(``rlgrasp.envs.experts``): a subclass names the phase that follows the close (``HOLD``) and says
what it does then (``hold_step``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from rlgrasp.envs.experts.observation import flat_observation

FINGER_REACH = 0.035  # m below the object's top at which the fingertips close on a tall object
FLOOR_CLEARANCE = 0.012  # m above the object's bottom: the lowest grasp height
# Widths closer than this are a tie: the hand keeps the yaw it has. Without the margin, a cube's two
# near-equal sides swap places with the observation's noise and the hand turns back and forth.
WIDTH_TIE = 0.005


def quat_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix of an (x, y, z, w) quaternion (normalised first: observations are noisy)."""
    x, y, z, w = np.asarray(quat, dtype=float) / max(float(np.linalg.norm(quat)), 1e-9)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def half_height(quat: np.ndarray, extents: np.ndarray) -> float:
    """Half the vertical extent of a box of ``extents`` at ``quat``."""
    return 0.5 * float(np.abs(quat_matrix(quat)[2]) @ extents)


def _wrap_half_turn(angle: float) -> float:
    """An angle into [-pi/2, pi/2): a parallel gripper is symmetric under a half turn."""
    return (angle + math.pi / 2) % math.pi - math.pi / 2


def grasp_plan(
    quat: np.ndarray,
    extents: np.ndarray,
    centre_z: float,
    finger_reach: float = FINGER_REACH,
    floor_clearance: float = FLOOR_CLEARANCE,
    current_yaw: float = 0.0,
) -> tuple[float, float, float]:
    """(hand yaw, grasp-point height, width across the fingers) for a top-down grasp: the grasp
    point ``finger_reach`` below the object's top, at least ``floor_clearance`` above its bottom.

    The fingers close along the hand's y axis, which at yaw ``t`` points along (-sin t, cos t);
    they must close along the object's narrower horizontal axis, or, where the two widths tie
    (within ``WIDTH_TIE``), along the one nearer the hand's ``current_yaw``.
    """
    rotation = quat_matrix(quat)
    vertical = int(np.argmax(np.abs(rotation[2])))
    half = 0.5 * float(np.abs(rotation[2]) @ extents)
    horizontal = [i for i in range(3) if i != vertical]
    candidates = []
    for i in horizontal:
        axis = rotation[:, i]
        yaw = _wrap_half_turn(math.atan2(axis[1], axis[0]) - math.pi / 2)
        candidates.append((float(extents[i]), yaw))
    narrowest = min(width for width, _ in candidates)
    ties = [(abs(yaw - current_yaw), yaw, w) for w, yaw in candidates if w <= narrowest + WIDTH_TIE]
    _, yaw, width = min(ties)
    bottom, top = centre_z - half, centre_z + half
    return yaw, max(bottom + floor_clearance, top - finger_reach), width


#: The phases in which an expert grasps the object (``ScriptedExpert.grasp_step``).
GRASP_PHASES = ("approach", "descend", "close")


class ScriptedExpert:
    """Approach above the object, turn, descend, close, lift; start over if the object is lost."""

    #: The phase after the fingers closed.
    HOLD = "lift"

    def __init__(
        self,
        obs_slices: Mapping[str, slice],
        action_dim: int = 4,
        ee_step: float = 0.04,
        yaw_step: float = 0.2,
        hover: float = 0.06,
        lift_to: float = 0.15,
        close_steps: int = 4,
        gain: float = 0.8,
        finger_reach: float = FINGER_REACH,
        floor_clearance: float = FLOOR_CLEARANCE,
    ):
        self.s = obs_slices
        self.finger_reach, self.floor_clearance = finger_reach, floor_clearance
        self.action_dim = action_dim
        self.use_yaw = action_dim == 5
        self.ee_step, self.yaw_step = ee_step, yaw_step
        self.hover, self.lift_to = hover, lift_to
        self.close_steps, self.gain = close_steps, gain
        self.reset()

    @classmethod
    def for_env(cls, env: Any, **settings: Any) -> ScriptedExpert:
        """The expert of ``env`` (a grasp env, or a wrapper of one), with its arm's grasp settings
        (the description's ``expert`` key) unless ``settings`` give them."""
        base = getattr(env, "unwrapped", env)
        spec = getattr(getattr(base, "robot", None), "spec", None)
        arm = dict(getattr(spec, "expert", None) or {})
        slices = env.obs_slices if hasattr(env, "obs_slices") else base.obs_slices
        return cls(slices, action_dim=int(env.action_space.shape[0]), **{**arm, **settings})

    def reset(self) -> None:
        self.phase = "approach"
        self._closing = 0
        self._lost = 0
        self._yaw = 0.0  # the yaw this expert has commanded: the env starts each episode at 0

    def _move(
        self,
        grasp: np.ndarray,
        target: np.ndarray,
        yaw: float,
        open_fingers: bool,
        gain: float | None = None,
    ) -> np.ndarray:
        """The action taking the grasp point ``gain`` (default: the expert's) of the way to ``target``
        and the hand towards ``yaw``, the fingers open or closed."""
        action = np.zeros(self.action_dim, np.float32)
        gain = self.gain if gain is None else gain
        action[:3] = np.clip(gain * (target - grasp) / self.ee_step, -1.0, 1.0)
        if self.use_yaw:
            action[3] = np.clip((yaw - self._yaw) / self.yaw_step, -1.0, 1.0)
            self._yaw = float(np.clip(self._yaw + action[3] * self.yaw_step, -math.pi / 2, math.pi / 2))
        action[-1] = 1.0 if open_fingers else -1.0
        return action

    def __call__(self, obs: Any) -> np.ndarray:
        """The action for ``obs``: the flat vector, a goal task's Dict or a camera env's Dict."""
        obs = flat_observation(obs)
        if self.phase in GRASP_PHASES:
            return self.grasp_step(obs)
        return self.hold_step(obs)

    def grasp_step(self, obs: np.ndarray) -> np.ndarray:
        """Approach above the object, turn, descend, close; then the phase ``HOLD``."""
        s = self.s
        grasp = obs[s["grasp_pos"]].astype(float)
        centre = grasp + obs[s["object_minus_grasp"]]
        yaw, grasp_z, _ = grasp_plan(
            obs[s["object_quat"]],
            obs[s["object_extents"]],
            centre[2],
            self.finger_reach,
            self.floor_clearance,
            self._yaw,
        )
        yaw = yaw if self.use_yaw else 0.0
        target = np.array([centre[0], centre[1], grasp_z])
        flat = np.linalg.norm(target[:2] - grasp[:2])
        if self.phase == "approach":
            above = target + [0.0, 0.0, self.hover]
            turned = abs(yaw - self._yaw) < 0.1
            if flat < 0.01 and abs(grasp[2] - above[2]) < 0.02 and turned:
                self.phase = "descend"
            return self._move(grasp, above, yaw, open_fingers=True)
        if self.phase == "descend":
            if abs(target[2] - grasp[2]) < 0.01:
                self.phase = "close"
            if flat > 0.02:  # the object moved: go back up
                self.phase = "approach"
            return self._move(grasp, target, self._yaw, open_fingers=True)
        self._closing += 1
        if self._closing >= self.close_steps:
            self.phase, self._closing, self._lost = self.HOLD, 0, 0
        return self._move(grasp, target, self._yaw, open_fingers=False)

    def lost_grip(self, obs: np.ndarray, steps: int = 3) -> bool:
        """The object out of the fingers for ``steps`` steps running (then the phase is ``approach``)."""
        self._lost = 0 if obs[self.s["grasped"]][0] > 0.5 else self._lost + 1
        if self._lost >= steps:
            self.phase = "approach"
            return True
        return False

    def hold_step(self, obs: np.ndarray) -> np.ndarray:
        """Lift: an object out of the fingers for a few steps means try again."""
        grasp = obs[self.s["grasp_pos"]].astype(float)
        self.lost_grip(obs)
        return self._move(grasp, np.array([grasp[0], grasp[1], self.lift_to]), self._yaw, open_fingers=False)
