"""Control modes: how an action in [-1, 1] becomes motor commands for a ``Robot``.

Every mode's last action entry is the absolute finger-width target (-1 closed, +1 open), so a
policy always keeps squeezing while it holds. A mode owns what it remembers between steps (the
commanded yaw of ``EEDelta``) and resets it with the episode.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from rlgrasp.envs.robot import Robot

WORKSPACE_LOW = np.array([0.3, -0.35, 0.005])  # grasp-point targets are clipped to this box;
WORKSPACE_HIGH = np.array([0.85, 0.35, 0.45])  # the z floor keeps the fingertips off the ground


@dataclass
class ControlConfig:
    """``env.control``: how actions drive the arm; each mode reads its own settings."""

    mode: str = "ee_delta"  # ee_delta | joint_delta | joint_torque
    ee_step: float = 0.04  # ee_delta: m the grasp point moves per unit action
    ee_yaw: bool = False  # ee_delta: the hand's yaw is an action too (the fingers turn to the object)
    yaw_step: float = 0.2  # ee_delta with ee_yaw: rad per unit action
    joint_step: float = 0.05  # joint_delta: rad per unit action
    torque_fraction: float = 0.3  # joint_torque: the share of each joint's torque limit per unit action
    gravity_compensation: bool = True  # joint_torque: the arm's weight is held for the policy

    def __post_init__(self) -> None:
        if self.mode not in CONTROL_MODES:
            raise ValueError(f"unknown control.mode {self.mode!r}; valid modes: {', '.join(CONTROL_MODES)}")


class ControlMode(ABC):
    """Turns one action into the robot's commands for the ``substeps`` physics steps of a control step."""

    def __init__(self, robot: Robot):
        self.robot = robot

    @property
    @abstractmethod
    def motion_dim(self) -> int:
        """Action entries before the finger target."""

    @property
    def action_dim(self) -> int:
        return self.motion_dim + 1

    def reset(self, episode: dict[str, Any]) -> None:
        """Position control at the episode's gains, holding the start pose."""
        self.robot.use_position_control(episode["position_gain_scale"], episode["finger_force"])
        self.robot.command_arm(self.robot.joint_state()[0])

    def apply(
        self,
        action: np.ndarray,
        substeps: int,
        step: Callable[[], None],
        readings: Mapping[str, Any] | None = None,
    ) -> None:
        """``readings``: the robot's readings taken since the last physics step (the env's last
        observation), so that the target need not read the joints or the grasp point again."""
        robot = self.robot
        robot.command_fingers((action[-1] + 1.0) / 2.0 * robot.max_finger_width)
        robot.command_arm(self.arm_target(action, readings))
        for _ in range(substeps):
            step()

    def arm_target(
        self, action: np.ndarray, readings: Mapping[str, Any] | None = None
    ) -> np.ndarray:  # pragma: no cover - position modes
        raise NotImplementedError


class EEDelta(ControlMode):
    """Grasp-point (dx, dy, dz[, dyaw]) x ``ee_step`` m (``yaw_step`` rad), solved by IK, gripper down."""

    def __init__(self, robot: Robot, ee_step: float = 0.04, ee_yaw: bool = False, yaw_step: float = 0.2):
        super().__init__(robot)
        self.ee_step, self.ee_yaw, self.yaw_step = ee_step, ee_yaw, yaw_step
        self.yaw = 0.0

    @property
    def motion_dim(self) -> int:
        return 3 + int(self.ee_yaw)

    def reset(self, episode: dict[str, Any]) -> None:
        super().reset(episode)
        self.yaw = 0.0

    def arm_target(self, action: np.ndarray, readings: Mapping[str, Any] | None = None) -> np.ndarray:
        robot = self.robot
        grasp_pos = robot.grasp_point()[0] if readings is None else readings["grasp_pos"]
        # np.minimum/np.maximum: np.clip's result for finite values, at a fraction of its call cost
        target = np.minimum(np.maximum(grasp_pos + action[:3] * self.ee_step, WORKSPACE_LOW), WORKSPACE_HIGH)
        if not self.ee_yaw:
            return robot.inverse_kinematics(target)
        self.yaw = float(np.clip(self.yaw + action[3] * self.yaw_step, -math.pi / 2, math.pi / 2))
        return robot.inverse_kinematics(target, robot.gripper_down(self.yaw))


class JointDelta(ControlMode):
    """Arm joint deltas x ``joint_step`` rad, within the joint limits."""

    def __init__(self, robot: Robot, joint_step: float = 0.05):
        super().__init__(robot)
        self.joint_step = joint_step

    @property
    def motion_dim(self) -> int:
        return self.robot.arm_dof

    def arm_target(self, action: np.ndarray, readings: Mapping[str, Any] | None = None) -> np.ndarray:
        q = self.robot.joint_state()[0] if readings is None else readings["arm_q"]
        return np.clip(q + action[: self.motion_dim] * self.joint_step, self.robot.lower, self.robot.upper)


class JointTorque(ControlMode):
    """Torques x ``torque_fraction`` of each joint's effort limit, re-sent every physics substep
    (a torque lapses after one step), plus gravity compensation unless disabled."""

    def __init__(self, robot: Robot, torque_fraction: float = 0.3, gravity_compensation: bool = True):
        super().__init__(robot)
        self.torque_fraction, self.gravity_compensation = torque_fraction, gravity_compensation

    @property
    def motion_dim(self) -> int:
        return self.robot.arm_dof

    def reset(self, episode: dict[str, Any]) -> None:
        self.robot.use_torque_control(episode["finger_force"])

    def apply(
        self,
        action: np.ndarray,
        substeps: int,
        step: Callable[[], None],
        readings: Mapping[str, Any] | None = None,
    ) -> None:
        robot = self.robot
        robot.command_fingers((action[-1] + 1.0) / 2.0 * robot.max_finger_width)
        tau = action[: self.motion_dim] * self.torque_fraction * robot.max_torque
        for _ in range(substeps):
            robot.apply_torques(tau + robot.gravity_torques() if self.gravity_compensation else tau)
            step()


CONTROL_MODES = ("ee_delta", "joint_delta", "joint_torque")


def make_control(config: ControlConfig, robot: Robot) -> ControlMode:
    """The control mode ``config.mode`` on ``robot``, with that mode's settings."""
    if config.mode == "ee_delta":
        return EEDelta(robot, config.ee_step, config.ee_yaw, config.yaw_step)
    if config.mode == "joint_delta":
        return JointDelta(robot, config.joint_step)
    if not robot.torque_control:
        raise ValueError(
            "control.mode=joint_torque: this arm's model has no meaningful dynamics "
            "(robot.torque_control=false); use ee_delta or joint_delta"
        )
    return JointTorque(robot, config.torque_fraction, config.gravity_compensation)
