"""The PyBullet world: one private client, the ground, and a pool of cubes of different sizes.

A cube's size cannot change after creation, so size randomization picks one body from a small
pool; the others are parked far away as static bodies (mass 0), where they cost the solver nothing.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

CUBE_EDGE = 0.05  # m, edge of cube_small.urdf


def data_path(name: str) -> str:
    """Absolute path of a model shipped with pybullet_data; FileNotFoundError if it is missing."""
    path = name if os.path.isabs(name) else os.path.join(pybullet_data.getDataPath(), name)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"model file not found: {path}")
    return path


class Scene:
    """Owns the physics client. Connect inside the process that steps it (never before a fork)."""

    def __init__(
        self,
        time_step: float = 1.0 / 240.0,
        gui: bool = False,
        cube_urdf: str = "cube_small.urdf",
        cube_scales: Sequence[float] = (0.8, 0.9, 1.0, 1.1, 1.2),
        solver_iterations: int = 20,
    ):
        cube_path = data_path(cube_urdf)  # fail before connecting
        self.client = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        c = self.client
        c.setTimeStep(time_step)
        # Deterministic pairs: bit-identical replays after restoreState (RESEARCH.md section 1).
        # 20 solver iterations instead of PyBullet's 50 nearly double the physics speed, and the
        # scripted grasp succeeds as often (docs/BENCHMARKS.md).
        c.setPhysicsEngineParameter(
            deterministicOverlappingPairs=1, numSolverIterations=int(solver_iterations)
        )
        self.time_step = time_step
        self.plane = c.loadURDF(data_path("plane.urdf"))
        self.cube_scales = tuple(sorted(cube_scales))
        self.cubes = [
            c.loadURDF(cube_path, self._park_position(i, s), globalScaling=s)
            for i, s in enumerate(self.cube_scales)
        ]
        for body in self.cubes:
            c.changeDynamics(body, -1, mass=0.0)
        self.cube = self.cubes[self.cube_scales.index(1.0) if 1.0 in self.cube_scales else 0]
        self.cube_edge = CUBE_EDGE

    @staticmethod
    def _park_position(index: int, scale: float) -> list[float]:
        return [-5.0 - index, 5.0, CUBE_EDGE * scale / 2]

    def select_cube(self, scale: float) -> float:
        """Make the pool body nearest ``scale`` the active cube; return its actual scale."""
        index = min(range(len(self.cube_scales)), key=lambda i: abs(self.cube_scales[i] - scale))
        self.cube = self.cubes[index]
        self.cube_edge = CUBE_EDGE * self.cube_scales[index]
        return self.cube_scales[index]

    def park_cubes(self) -> None:
        """Return every cube to its parking spot as a static body."""
        for i, (body, s) in enumerate(zip(self.cubes, self.cube_scales)):
            self.client.changeDynamics(body, -1, mass=0.0)
            self.client.resetBasePositionAndOrientation(body, self._park_position(i, s), [0, 0, 0, 1])

    def close(self) -> None:
        try:
            self.client.disconnect()
        except pybullet.error:
            pass
