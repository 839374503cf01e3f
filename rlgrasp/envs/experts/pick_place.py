"""The pick-and-place expert: the lift expert's grasp, then the object's centre carried to the goal
and held there until the episode ends (success is measured at every step)."""

from __future__ import annotations

from typing import Any

import numpy as np

from rlgrasp.envs.experts.lift import ScriptedExpert, half_height

#: m the object is held above a goal on the table: it does not drag (the 5 cm threshold allows it).
TABLE_CLEARANCE = 0.012
#: The fraction of the remaining distance each carrying step commands. Below the grasp's 0.8: with
#: a step of action delay (the default preset's) 0.8 rings about the goal for the whole episode
#: (the loop x' = x + g e(t-1) decays as sqrt(g) a step, 0.89), 0.5 settles (0.71).
CARRY_GAIN = 0.5


class PickPlaceExpert(ScriptedExpert):
    """Grasp (approach, descend, close), carry the object's centre to the desired goal, hold it."""

    HOLD = "carry"

    def __init__(self, *args: Any, carry_gain: float = CARRY_GAIN, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.carry_gain = carry_gain

    def object_target(self, obs: np.ndarray) -> np.ndarray:
        """Where the object's centre should go: the goal, a little above the table if it lies on it."""
        s = self.s
        goal = obs[s["desired_goal"]].astype(float)
        floor = half_height(obs[s["object_quat"]], obs[s["object_extents"]]) + TABLE_CLEARANCE
        return np.array([goal[0], goal[1], max(goal[2], floor)])

    def hold_step(self, obs: np.ndarray) -> np.ndarray:
        """Carry: the hand moves by what separates the object from its target; a lost object means
        grasp again."""
        s = self.s
        grasp = obs[s["grasp_pos"]].astype(float)
        self.lost_grip(obs)
        offset = self.object_target(obs) - obs[s["object_pos"]]
        return self._move(grasp, grasp + offset, self._yaw, open_fingers=False, gain=self.carry_gain)
