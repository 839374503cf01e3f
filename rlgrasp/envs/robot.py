"""The robot seam: what the env and its control modes need from an arm with a gripper.

``Robot`` is the interface (load, reset, joint and gripper state, the grasp point, dynamics, the
motor commands, IK); ``Panda`` is its first implementation. A new arm is a new subclass plus a
config entry in ``ROBOTS``: the env, the control modes and the observation size themselves from
``arm_dof``, ``neutral_pose`` and the joint limits, never from the Panda's numbers.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import tempfile
from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.scene import data_path

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
        return {"arm_q": q, "arm_qd": qd, "finger_width": np.array([width]), "grasp_pos": grasp_pos,
                "grasp_vel": grasp_vel}

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

    @abstractmethod
    def inverse_kinematics(self, position: np.ndarray, orientation=GRIPPER_DOWN) -> np.ndarray:
        """Arm joint angles that put the grasp point at ``position`` with the given orientation."""


class Panda(Robot):
    """The Franka Panda of ``pybullet_data``: joint and link indices looked up by name."""

    ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
    FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
    FINGER_LINKS = ("panda_leftfinger", "panda_rightfinger")
    GRASP_LINK = "panda_grasptarget"  # a fixed link of the Panda URDF between the fingertips
    NOMINAL_POSITION_GAIN = 0.2  # twice PyBullet's default: the grasp point keeps up with 4 cm steps
    IK_ITERATIONS = 20  # fewer lag behind when reaching out along x; converged solves exit early

    neutral_pose = (0.0, 0.41, 0.0, -1.85, 0.0, 2.26, 0.79)
    max_finger_width = 0.08

    MOUNT_LINK = "panda_hand"
    MODEL = "franka_panda/panda.urdf"

    #: The links a wrist camera sees: the hand and what it carries.
    WRIST_LINKS = ("panda_hand", "panda_leftfinger", "panda_rightfinger", "panda_grasptarget")

    def __init__(self, client: BulletClient, urdf: str | None = None, render: str | None = None):
        """``render``: None (the model as it is), ``low_poly`` or ``wrist`` (low-poly, wrist links only)."""
        self.client = client
        path = data_path(urdf or self.MODEL)
        if render and urdf is None:
            path = low_poly_urdf(path, self.WRIST_LINKS if render == "wrist" else None)
        self.body = client.loadURDF(path, useFixedBase=True)
        joints, links = {}, {}
        for j in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, j)
            joints[info[1].decode()] = j
            links[info[12].decode()] = j
        self.arm = [joints[n] for n in self.ARM_JOINTS]
        self.fingers = [joints[n] for n in self.FINGER_JOINTS]
        self.finger_links = [links[n] for n in self.FINGER_LINKS]
        self.grasp_link = links[self.GRASP_LINK]
        self.mount_link = links[self.MOUNT_LINK]
        self.link_names = {j: name for name, j in links.items()}
        self.visible_links = list(range(-1, client.getNumJoints(self.body)))
        infos = [client.getJointInfo(self.body, j) for j in self.arm]
        self.lower = np.array([i[8] for i in infos])
        self.upper = np.array([i[9] for i in infos])
        self.max_torque = np.array([i[10] for i in infos])
        self.movable = self.arm + self.fingers
        self.position_gain = self.NOMINAL_POSITION_GAIN
        self.finger_force = 20.0

    # --- state ---------------------------------------------------------------------------------
    def reset(self, arm_q: Sequence[float], finger_width: float | None = None) -> None:
        width = self.max_finger_width if finger_width is None else finger_width
        for j, q in zip(self.arm, arm_q):
            self.client.resetJointState(self.body, j, q)
        for j in self.fingers:
            self.client.resetJointState(self.body, j, width / 2)

    def joint_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        states = self.client.getJointStates(self.body, self.movable)
        q = np.array([s[0] for s in states])
        qd = np.array([s[1] for s in states])
        n = len(self.arm)
        return q[:n], qd[:n], float(q[n] + q[n + 1])

    def grasp_point(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.client.getLinkState(
            self.body, self.grasp_link, computeLinkVelocity=1, computeForwardKinematics=1
        )
        return np.array(state[4]), np.array(state[6])

    def wrist_links(self) -> list[int]:
        return [j for j, name in self.link_names.items() if name in self.WRIST_LINKS]

    def camera_mount(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.client.getLinkState(self.body, self.mount_link, computeForwardKinematics=1)
        return np.array(state[4]), np.array(state[5])

    # --- dynamics ------------------------------------------------------------------------------
    def set_dynamics(self, joint_damping: float, finger_friction: float) -> None:
        for j in self.arm:
            self.client.changeDynamics(self.body, j, jointDamping=joint_damping)
        for link in self.finger_links:
            self.client.changeDynamics(self.body, link, lateralFriction=finger_friction)

    # --- control -------------------------------------------------------------------------------
    def use_position_control(self, gain_scale: float = 1.0, finger_force: float = 20.0) -> None:
        self.position_gain = self.NOMINAL_POSITION_GAIN * gain_scale
        self.finger_force = finger_force

    def use_torque_control(self, finger_force: float = 20.0) -> None:
        """Release the default velocity motors, which would otherwise cancel applied torques."""
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
        half = float(np.clip(width, 0.0, self.max_finger_width)) / 2
        self.client.setJointMotorControlArray(
            self.body,
            self.fingers,
            pybullet.POSITION_CONTROL,
            targetPositions=[half, half],
            forces=[self.finger_force] * 2,
        )

    def apply_torques(self, tau: np.ndarray) -> None:
        self.client.setJointMotorControlArray(
            self.body,
            self.arm,
            pybullet.TORQUE_CONTROL,
            forces=np.clip(tau, -self.max_torque, self.max_torque),
        )

    def gravity_torques(self) -> np.ndarray:
        """Inverse dynamics at rest."""
        states = self.client.getJointStates(self.body, self.movable)
        q = [s[0] for s in states]
        zeros = [0.0] * len(q)
        return np.array(self.client.calculateInverseDynamics(self.body, q, zeros, zeros)[: len(self.arm)])

    def inverse_kinematics(self, position: np.ndarray, orientation=GRIPPER_DOWN) -> np.ndarray:
        q = self.client.calculateInverseKinematics(
            self.body,
            self.grasp_link,
            position,
            orientation,
            maxNumIterations=self.IK_ITERATIONS,
        )
        return np.clip(np.array(q[: len(self.arm)]), self.lower, self.upper)


def low_poly_urdf(path: str, visible_links: Sequence[str] | None = None) -> str:
    """The same URDF with each visual mesh replaced by its collision mesh, for cameras; with
    ``visible_links``, the other links lose their visuals altogether (a wrist camera never sees them).

    Rendering cost on the CPU follows the robot's visual triangles: the Panda's visual meshes make a
    64x64 image cost ten times what its collision meshes do, and every visual shape costs a sync per
    image even when transparent. Physics reads only the collision shapes, so the robot moves exactly
    as before. Written once per machine into the temp directory (mesh paths made absolute),
    atomically: several workers may ask at once.
    """
    text = open(path).read()
    folder = os.path.dirname(path)
    low = text.replace("package://meshes/visual/", os.path.join(folder, "meshes", "collision", ""))
    low = low.replace("package://", folder + os.sep)
    if visible_links is not None:
        def strip(link: re.Match) -> str:
            text = link.group(0)
            name = re.search(r'<link\s+name="([^"]+)"', text).group(1)
            return text if name in visible_links else re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)

        low = re.sub(r"<link\s+name=.*?</link>", strip, low, flags=re.S)
    digest = hashlib.sha1(low.encode()).hexdigest()[:12]
    target = os.path.join(tempfile.gettempdir(), f"rlgrasp-lowpoly-{digest}.urdf")
    if not os.path.isfile(target):
        fd, scratch = tempfile.mkstemp(suffix=".urdf", dir=tempfile.gettempdir())
        with os.fdopen(fd, "w") as f:
            f.write(low)
        os.replace(scratch, target)
    return target


#: ``env.robot`` names -> the class that loads that arm.
ROBOTS: dict[str, type[Robot]] = {"panda": Panda}


def make_robot(name: str, client: BulletClient, model: str | None = None, render: str | None = None) -> Robot:
    """The arm called ``name``; ``model`` overrides its model file (a path or a pybullet_data name);
    ``render`` asks for the model cameras render cheaply (``low_poly``, or ``wrist``: only what a
    wrist camera sees)."""
    if name not in ROBOTS:
        raise ValueError(f"unknown robot {name!r}; valid robots: {', '.join(ROBOTS)}")
    return ROBOTS[name](client, model, render=render)
