"""A scripted grasp that acts only through ``ee_delta`` actions and the observation vector.

It proves the task solvable under each randomization preset and is the baseline a learned policy
is compared with.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


class ScriptedExpert:
    """Approach above the cube, descend, close, lift; start over if the cube is lost."""

    def __init__(
        self,
        obs_slices: Mapping[str, slice],
        action_dim: int = 4,
        ee_step: float = 0.04,
        hover: float = 0.06,
        lift_to: float = 0.15,
        close_steps: int = 4,
        gain: float = 0.8,
    ):
        self.s = obs_slices
        self.action_dim = action_dim
        self.ee_step, self.hover, self.lift_to = ee_step, hover, lift_to
        self.close_steps, self.gain = close_steps, gain
        self.reset()

    def reset(self) -> None:
        self.phase = "approach"
        self._closing = 0

    def _move(self, grasp: np.ndarray, target: np.ndarray, open_fingers: bool) -> np.ndarray:
        action = np.zeros(self.action_dim, np.float32)
        action[:3] = np.clip(self.gain * (target - grasp) / self.ee_step, -1.0, 1.0)
        action[-1] = 1.0 if open_fingers else -1.0
        return action

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        grasp, cube = obs[self.s["grasp_pos"]], obs[self.s["cube_pos"]]
        error = cube - grasp
        if self.phase == "approach":
            if np.linalg.norm(error[:2]) < 0.01 and abs(grasp[2] - cube[2] - self.hover) < 0.02:
                self.phase = "descend"
            return self._move(grasp, cube + [0.0, 0.0, self.hover], open_fingers=True)
        if self.phase == "descend":
            if abs(error[2]) < 0.01:
                self.phase = "close"
            if np.linalg.norm(error[:2]) > 0.02:  # the cube moved: go back up
                self.phase = "approach"
            return self._move(grasp, cube, open_fingers=True)
        if self.phase == "close":
            self._closing += 1
            if self._closing >= self.close_steps:
                self.phase, self._closing = "lift", 0
            return self._move(grasp, cube, open_fingers=False)
        # lift: a lost cube means try again
        if np.linalg.norm(error) > 0.04:
            self.phase = "approach"
        target = np.array([grasp[0], grasp[1], self.lift_to])
        return self._move(grasp, target, open_fingers=False)
