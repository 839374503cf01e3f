"""The robot seam: what the env and its control modes need from an arm with a gripper.

``Robot`` is the interface (load, reset, joint and gripper state, the grasp point, dynamics, the
motor commands, IK); ``rlgrasp.envs.arm.ArmRobot`` implements it for any arm a ``RobotSpec``
describes. The env, the control modes and the observation size themselves from ``arm_dof``,
``neutral_pose`` and the joint limits, never from one arm's numbers.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

GRIPPER_DOWN = pybullet.getQuaternionFromEuler((math.pi, 0.0, 0.0))


class Robot(ABC):
    """One arm body in one physics client. Owns its body: loads it, resets it, drives it."""

    #: Start pose of the arm joints (rad) and the widest finger opening (m).
    neutral_pose: tuple[float, ...]
    max_finger_width: float
    #: Links whose contact with the object counts as a grasp (both must touch).
    finger_links: list[int]
    body: int
    lower: np.ndarray
    upper: np.ndarray
    max_torque: np.ndarray
    finger_force: float
    client: BulletClient
    #: Links cameras may see (``show_only``); visual randomization recolours these.
    visible_links: list[int]
    #: Euler angles of the grasp frame when the fingers point down and close along world y.
    down_euler: tuple[float, float, float] = (math.pi, 0.0, 0.0)
    #: Whether joint torques are a meaningful action for this arm's model.
    torque_control: bool = True

    @property
    def arm_dof(self) -> int:
        return len(self.neutral_pose)

    # --- state ---------------------------------------------------------------------------------
    @abstractmethod
    def reset(self, arm_q: Sequence[float], finger_width: float | None = None) -> None:
        """Teleport the joints (no physics step)."""

    @abstractmethod
    def joint_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Arm positions, arm velocities, finger opening width."""

    @abstractmethod
    def grasp_point(self) -> tuple[np.ndarray, np.ndarray]:
        """World position and linear velocity of the point between the fingertips."""

    @abstractmethod
    def camera_mount(self) -> tuple[np.ndarray, np.ndarray]:
        """World position and quaternion of the link a wrist camera is fixed to (its z axis points
        along the fingers)."""

    def readings(self) -> dict[str, np.ndarray]:
        """The robot's proprioception, by observation part name."""
        q, qd, width = self.joint_state()
        grasp_pos, grasp_vel = self.grasp_point()
        return {
            "arm_q": q,
            "arm_qd": qd,
            "finger_width": np.array([width]),
            "grasp_pos": grasp_pos,
            "grasp_vel": grasp_vel,
        }

    @abstractmethod
    def wrist_links(self) -> list[int]:
        """The links a wrist camera can see (the mount and what it carries)."""

    def show_only(self, links: list[int]) -> None:
        """Hide every other link from cameras: the CPU renderer skips transparent shapes, and a
        wrist camera never sees the links behind it. Physics is not affected."""
        for link in range(-1, self.client.getNumJoints(self.body)):
            if link not in links:
                self.client.changeVisualShape(self.body, link, rgbaColor=[1.0, 1.0, 1.0, 0.0])
        self.visible_links = list(links)

    # --- dynamics and control ------------------------------------------------------------------
    @abstractmethod
    def set_dynamics(self, joint_damping: float, finger_friction: float) -> None: ...

    @abstractmethod
    def use_position_control(self, gain_scale: float = 1.0, finger_force: float = 20.0) -> None: ...

    @abstractmethod
    def use_torque_control(self, finger_force: float = 20.0) -> None: ...

    @abstractmethod
    def command_arm(self, q_target: np.ndarray) -> None: ...

    @abstractmethod
    def command_fingers(self, width: float) -> None: ...

    @abstractmethod
    def apply_torques(self, tau: np.ndarray) -> None:
        """Must be called before every physics step: an applied torque lapses after one step."""

    @abstractmethod
    def gravity_torques(self) -> np.ndarray:
        """Torques that hold the arm still where it is."""

    def gripper_down(self, yaw: float = 0.0) -> tuple[float, ...]:
        """The quaternion of the grasp frame pointing down, turned by ``yaw`` about the world z axis
        (Euler angles compose as Rz Ry Rx, so a turn about world z adds to the last angle)."""
        roll, pitch, yaw0 = self.down_euler
        return self.client.getQuaternionFromEuler((roll, pitch, yaw0 + yaw))

    @abstractmethod
    def inverse_kinematics(self, position: np.ndarray, orientation=None) -> np.ndarray:
        """Arm joint angles that put the grasp point at ``position`` with the given orientation
        (None: ``gripper_down()``)."""
