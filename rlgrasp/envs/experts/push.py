"""The push expert: fingers closed, the hand behind the object opposite the goal at low height, then
pushing along the line to the goal; when the object drifts off the line or the hand gets beside it,
up over it and round behind it again."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from rlgrasp.envs.experts.lift import ScriptedExpert, _wrap_half_turn, half_height, quat_matrix
from rlgrasp.envs.experts.observation import flat_observation

#: m the closed fingers reach from the grasp point along the hand's x axis and along its y axis
#: (the Panda's closed pads: 2.9 cm across, 6 cm along the closing axis).
FINGER_HALF_X = 0.015
FINGER_HALF_Y = 0.03


def support(quat: np.ndarray, extents: np.ndarray, direction: np.ndarray) -> float:
    """How far a box of ``extents`` at ``quat`` reaches from its centre along the horizontal unit
    ``direction``."""
    local = quat_matrix(quat).T @ np.array([direction[0], direction[1], 0.0])
    return 0.5 * float(np.abs(local) @ extents)


def nearest_yaw(heading: float, current: float) -> float:
    """The hand yaw (within the hand's +-pi/2) pointing its x axis along ``heading`` or against it,
    whichever is nearer ``current``: near +-pi/2 the hand stays on its side rather than turn round."""
    yaw = _wrap_half_turn(heading)
    other = float(np.clip(yaw + math.pi if yaw < 0 else yaw - math.pi, -math.pi / 2, math.pi / 2))
    return other if abs(other - current) < abs(yaw - current) else yaw


class PushExpert(ScriptedExpert):
    """``approach`` above and behind the object, ``descend`` to pushing height, ``push`` to the goal."""

    def __init__(
        self,
        *args: Any,
        standoff: float = 0.02,
        push_gain: float = 0.5,
        push_speed: float = 0.03,
        lateral_gain: float = 0.5,
        off_line: float = 0.04,
        descend_gain: float = 0.5,
        push_height: float = 0.03,
        clearance: float = 0.03,
        done_within: float = 0.015,
        beside: float = 0.01,
        travel: float = 0.04,
        **kwargs: Any,
    ):
        super().__init__(*args, **kwargs)
        self.standoff, self.push_gain, self.push_speed = standoff, push_gain, push_speed
        self.lateral_gain, self.off_line, self.descend_gain = lateral_gain, off_line, descend_gain
        self.push_height, self.clearance = push_height, clearance
        self.done_within, self.beside, self.travel = done_within, beside, travel

    def __call__(self, obs: Any) -> np.ndarray:
        obs = flat_observation(obs)
        s = self.s
        grasp = obs[s["grasp_pos"]].astype(float)
        centre = grasp + obs[s["object_minus_grasp"]]
        quat, extents = obs[s["object_quat"]], obs[s["object_extents"]]
        to_goal = obs[s["desired_goal"]][:2] - obs[s["object_pos"]][:2]
        distance = float(np.linalg.norm(to_goal))
        if distance < self.done_within:  # there: stay put
            return self._move(grasp, grasp, self._yaw, open_fingers=False)
        u = to_goal / distance
        heading = math.atan2(u[1], u[0])
        # The hand's x axis along the push (either way: the closed fingers are symmetric under a half
        # turn), so the fingers' 6 cm side pushes; of the two, the one nearer the hand's yaw.
        yaw = nearest_yaw(heading, self._yaw) if self.use_yaw else 0.0
        turn = heading - self._yaw
        hand = abs(math.cos(turn)) * FINGER_HALF_X + abs(math.sin(turn)) * FINGER_HALF_Y
        half = support(quat, extents, u)
        contact = half + hand  # grasp point to object centre when touching
        behind = centre[:2] - u * (contact + self.standoff)
        relative = grasp[:2] - centre[:2]
        along, across = float(relative @ u), float(u[0] * relative[1] - u[1] * relative[0])
        safe = centre[2] + half_height(quat, extents) + self.clearance
        if self.phase == "push":
            # off the line, or level with the object's centre (the pads' 6 cm push a turned cube's
            # corner off to one side: along alone says little)
            if abs(across) > self.off_line or along > -self.beside:
                self.phase = "approach"
            else:
                # through the object along the line at a speed that falls as the goal nears, and
                # sideways back onto the line (a push moves the hand, the object's contact and all:
                # a target at the contact point would stall short of it)
                speed = min(self.push_speed, self.push_gain * distance)
                normal = np.array([-u[1], u[0]])
                shift = u * speed - normal * across * self.lateral_gain
                target = np.array([*(grasp[:2] + shift), grasp[2] + 0.5 * (self.push_height - grasp[2])])
                return self._move(grasp, target, yaw, open_fingers=False, gain=1.0)
        if self.phase == "descend":
            if abs(across) > self.off_line or along > -self.beside:
                self.phase = "approach"
            else:
                if grasp[2] - self.push_height < 0.01:
                    self.phase = "push"
                down = np.array([*behind, self.push_height])
                return self._move(grasp, down, self._yaw, open_fingers=False, gain=self.descend_gain)
        # approach: straight up first when low (not to sweep the object away), then over to above
        # the spot behind it
        if grasp[2] < safe - 0.015 and float(np.linalg.norm(grasp[:2] - behind)) > 0.015:
            return self._move(grasp, np.array([*grasp[:2], safe]), yaw, open_fingers=False)
        # far from the spot: higher still, so that the hand overshooting downwards (action delay)
        # misses the object
        far = float(np.linalg.norm(grasp[:2] - behind))
        if far < 0.015 and abs(yaw - self._yaw) < 0.15:
            self.phase = "descend"
        height = safe + (self.travel if far > 0.03 else 0.0)
        return self._move(grasp, np.array([*behind, height]), yaw, open_fingers=False)
