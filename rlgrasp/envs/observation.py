"""The observation, assembled from named parts.

Each part is a reading of the robot (proprioception), of the task's object (privileged: a real
robot has no such sensor) or of the env itself (the previous action). ``ObservationLayout`` orders
the parts into one float32 vector and knows each part's slice; sensor noise applies to the parts
marked ``noisy``. A policy that must run on a robot reads only ``PROPRIOCEPTION`` plus cameras; a
teacher or a critic may read the whole vector (``privileged``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Part:
    name: str
    size: int
    #: Sensor noise applies (a measured quantity, not a flag or the agent's own action).
    noisy: bool = True


def full_parts(arm_dof: int, action_dim: int, object_cells: int = 0) -> list[Part]:
    """Every state part, in the order of the flat observation every state policy reads; with a
    camera's ``object_cells`` (k > 0), its k x k map of the object's pixels last (a training label
    for a camera learner, ``rlgrasp.envs.cameras.object_cells``), after the parts it leaves in place."""
    cells = [Part("object_cells", object_cells * object_cells, noisy=False)] if object_cells else []
    return [
        Part("arm_q", arm_dof),
        Part("arm_qd", arm_dof),
        Part("finger_width", 1),
        Part("grasp_pos", 3),
        Part("grasp_vel", 3),
        Part("object_pos", 3),
        Part("object_quat", 4),
        Part("object_linvel", 3),
        Part("object_angvel", 3),
        Part("object_minus_grasp", 3),
        Part("object_extents", 3),
        Part("grasped", 1, noisy=False),
        Part("prev_action", action_dim, noisy=False),
        *cells,
    ]


#: What the robot itself senses: joints, gripper, where its grasp point is, what it last did.
PROPRIOCEPTION = ("arm_q", "arm_qd", "finger_width", "grasp_pos", "grasp_vel", "prev_action")


class ObservationLayout:
    """Named parts -> one float32 vector, with each part's slice (``slices``) for readers."""

    def __init__(self, parts: Sequence[Part]):
        self.parts = list(parts)
        self.slices: dict[str, slice] = {}
        start = 0
        for part in self.parts:
            self.slices[part.name] = slice(start, start + part.size)
            start += part.size
        self.size = start
        noisy = [p for p in self.parts if p.noisy]
        # Noise is drawn for the noisy parts' entries, in layout order.
        self.noisy_index = (
            np.concatenate([np.arange(self.slices[p.name].start, self.slices[p.name].stop) for p in noisy])
            if noisy
            else np.zeros(0, np.int64)
        )

    @property
    def noisy_size(self) -> int:
        return int(self.noisy_index.size)

    def assemble(self, readings: Mapping[str, np.ndarray]) -> np.ndarray:
        # Each part written into its slice: the float32 values a float64 concatenation cast to
        # float32 gives, without the intermediate arrays.
        vector = np.empty(self.size, np.float32)
        for name, where in self.slices.items():
            vector[where] = readings[name]
        return vector

    def add_noise(self, vector: np.ndarray, noise: np.ndarray) -> None:
        """Add ``noise`` (one value per noisy entry) in place."""
        if self.noisy_index.size and self.noisy_index[-1] == self.noisy_index.size - 1:
            vector[: self.noisy_index.size] += noise.astype(np.float32)  # noisy parts lead: one slice
        else:
            vector[self.noisy_index] += noise.astype(np.float32)

    def select(self, vector: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """The entries of the named parts, in the given order."""
        return np.concatenate([vector[self.slices[n]] for n in names])
