"""The Franka Panda: joint and link indices looked up by name, its control modes and IK."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.scene import data_path

ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
FINGER_LINKS = ("panda_leftfinger", "panda_rightfinger")
GRASP_LINK = "panda_grasptarget"  # a fixed link of the Panda URDF between the fingertips

NEUTRAL_POSE = (0.0, 0.41, 0.0, -1.85, 0.0, 2.26, 0.79)
MAX_FINGER_WIDTH = 0.08
GRIPPER_DOWN = pybullet.getQuaternionFromEuler((math.pi, 0.0, 0.0))
NOMINAL_POSITION_GAIN = 0.2  # twice PyBullet's default: the grasp point keeps up with 4 cm steps
IK_ITERATIONS = 20  # fewer lag behind when reaching out along x; converged solves exit early


class Panda:
    """Wraps one Panda body. Stateless apart from the control mode and the gains in force."""

    def __init__(self, client: BulletClient, urdf: str = "franka_panda/panda.urdf"):
        self.client = client
        self.body = client.loadURDF(data_path(urdf), useFixedBase=True)
        joints, links = {}, {}
        for j in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, j)
            joints[info[1].decode()] = j
            links[info[12].decode()] = j
        self.arm = [joints[n] for n in ARM_JOINTS]
        self.fingers = [joints[n] for n in FINGER_JOINTS]
        self.finger_links = [links[n] for n in FINGER_LINKS]
        self.grasp_link = links[GRASP_LINK]
        infos = [client.getJointInfo(self.body, j) for j in self.arm]
        self.lower = np.array([i[8] for i in infos])
        self.upper = np.array([i[9] for i in infos])
        self.max_torque = np.array([i[10] for i in infos])
        self.movable = self.arm + self.fingers
        self.position_gain = NOMINAL_POSITION_GAIN
        self.finger_force = 20.0
        self.torque_mode = False

    # --- state ---------------------------------------------------------------------------------
    def reset(self, arm_q: Sequence[float], finger_width: float = MAX_FINGER_WIDTH) -> None:
        for j, q in zip(self.arm, arm_q):
            self.client.resetJointState(self.body, j, q)
        for j in self.fingers:
            self.client.resetJointState(self.body, j, finger_width / 2)

    def joint_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Arm positions, arm velocities, finger width."""
        states = self.client.getJointStates(self.body, self.movable)
        q = np.array([s[0] for s in states])
        qd = np.array([s[1] for s in states])
        return q[:7], qd[:7], float(q[7] + q[8])

    def grasp_point(self) -> tuple[np.ndarray, np.ndarray]:
        """World position and linear velocity of the point between the fingertips."""
        state = self.client.getLinkState(
            self.body, self.grasp_link, computeLinkVelocity=1, computeForwardKinematics=1
        )
        return np.array(state[4]), np.array(state[6])

    # --- dynamics ------------------------------------------------------------------------------
    def set_dynamics(self, joint_damping: float, finger_friction: float) -> None:
        for j in self.arm:
            self.client.changeDynamics(self.body, j, jointDamping=joint_damping)
        for link in self.finger_links:
            self.client.changeDynamics(self.body, link, lateralFriction=finger_friction)

    # --- control -------------------------------------------------------------------------------
    def use_position_control(self, gain_scale: float = 1.0, finger_force: float = 20.0) -> None:
        self.torque_mode = False
        self.position_gain = NOMINAL_POSITION_GAIN * gain_scale
        self.finger_force = finger_force

    def use_torque_control(self, finger_force: float = 20.0) -> None:
        """Release the default velocity motors, which would otherwise cancel applied torques."""
        self.torque_mode = True
        self.finger_force = finger_force
        self.client.setJointMotorControlArray(
            self.body, self.arm, pybullet.VELOCITY_CONTROL, forces=[0.0] * len(self.arm)
        )

    def command_arm(self, q_target: np.ndarray) -> None:
        self.client.setJointMotorControlArray(
            self.body,
            self.arm,
            pybullet.POSITION_CONTROL,
            targetPositions=q_target,
            forces=self.max_torque,
            positionGains=[self.position_gain] * len(self.arm),
        )

    def command_fingers(self, width: float) -> None:
        half = float(np.clip(width, 0.0, MAX_FINGER_WIDTH)) / 2
        self.client.setJointMotorControlArray(
            self.body,
            self.fingers,
            pybullet.POSITION_CONTROL,
            targetPositions=[half, half],
            forces=[self.finger_force] * 2,
        )

    def apply_torques(self, tau: np.ndarray) -> None:
        """Must be called before every physics step: an applied torque lapses after one step."""
        self.client.setJointMotorControlArray(
            self.body,
            self.arm,
            pybullet.TORQUE_CONTROL,
            forces=np.clip(tau, -self.max_torque, self.max_torque),
        )

    def gravity_torques(self) -> np.ndarray:
        """Torques that hold the arm still where it is (inverse dynamics at rest)."""
        states = self.client.getJointStates(self.body, self.movable)
        q = [s[0] for s in states]
        zeros = [0.0] * len(q)
        return np.array(self.client.calculateInverseDynamics(self.body, q, zeros, zeros)[:7])

    def inverse_kinematics(self, position: np.ndarray, orientation=GRIPPER_DOWN) -> np.ndarray:
        """Arm joint angles that put the grasp point at ``position`` with the gripper down."""
        q = self.client.calculateInverseKinematics(
            self.body,
            self.grasp_link,
            position,
            orientation,
            maxNumIterations=IK_ITERATIONS,
        )
        return np.clip(np.array(q[:7]), self.lower, self.upper)
