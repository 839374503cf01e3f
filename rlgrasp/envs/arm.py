"""``ArmRobot``: the ``Robot`` of any arm a ``RobotSpec`` describes, joint and link indices looked up
by name in its URDF or SDF; ``Panda`` is that of the Franka Panda."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.collision_model import collision_variant, keep_mesh_inertia
from rlgrasp.envs.render_model import boxed_model, low_poly_urdf
from rlgrasp.envs.robot_base import Robot
from rlgrasp.envs.robot_check import check_model, check_spec_values
from rlgrasp.envs.robot_spec import RobotSpec, builtin_spec
from rlgrasp.envs.scene import data_path


class ArmRobot(Robot):
    """One arm body in one physics client, built from its spec."""

    def __init__(
        self,
        spec: RobotSpec,
        client: BulletClient,
        model: str | None = None,
        render: str | None = None,
        collision: str = "mesh",
    ):
        """``model`` overrides the spec's model file; ``render``: None (the model as it is),
        ``low_poly`` or ``wrist`` (low-poly, wrist links only) when the spec has a low-poly rule;
        ``collision``: a name of ``rlgrasp.envs.collision_model.COLLISION_MODELS``."""
        check_spec_values(spec)
        self.spec, self.client = spec, client
        key = "env.robot.model"
        try:
            path = data_path(model or spec.model)
        except FileNotFoundError as exc:
            raise FileNotFoundError(f"{key}: {exc}") from None
        if render and model is None and spec.low_poly_meshes:
            visible = self.wrist_names if render == "wrist" else None
            if spec.low_poly_meshes == "boxes":
                path = boxed_model(path, self.wrist_names, visible)
            else:
                path = low_poly_urdf(path, spec.low_poly_meshes, visible)
        mesh_path, path = path, collision_variant(path, spec.name, collision)
        self.body = self._load(path, key)
        keep_mesh_inertia(client, self.body, mesh_path, spec.name, collision)
        joints, links = {}, {}
        for j in range(client.getNumJoints(self.body)):
            info = client.getJointInfo(self.body, j)
            joints[info[1].decode()] = j
            links[info[12].decode()] = j
        check_model(spec, client, self.body, joints, links, path)
        self._index(joints, links)
        self._tie_mimic_joints(joints)
        self.neutral_pose = tuple(getattr(type(self), "neutral_pose", None) or spec.neutral_pose)
        self.max_finger_width = spec.max_finger_width
        self.down_euler = tuple(spec.gripper_down)
        self.torque_control = spec.torque_control
        self.visible_links = list(range(-1, client.getNumJoints(self.body)))
        self.position_gain = spec.position_gain
        self.finger_force = 20.0

    @property
    def wrist_names(self) -> tuple[str, ...]:
        return self.spec.wrist_links or self.spec.finger_links

    def _load(self, path: str, key: str) -> int:
        """A URDF with a fixed base, or the first body of an SDF made static, at the spec's base pose."""
        c, spec = self.client, self.spec
        orientation = c.getQuaternionFromEuler(spec.base_orientation)
        if path.lower().endswith(".urdf"):
            return c.loadURDF(path, spec.base_position, orientation, useFixedBase=True)
        if not path.lower().endswith(".sdf"):
            raise ValueError(f"{key}={path!r}: must be a .urdf or .sdf file")
        body = c.loadSDF(path)[0]
        c.resetBasePositionAndOrientation(body, spec.base_position, orientation)
        c.changeDynamics(body, -1, mass=0.0)  # a fixed base
        return body

    def _index(self, joints: dict[str, int], links: dict[str, int]) -> None:
        c, spec = self.client, self.spec
        self.arm = [joints[n] for n in spec.arm_joints]
        self.fingers = [joints[f.joint] for f in spec.fingers]
        self.finger_links = [links[n] for n in spec.finger_links]
        self.grasp_link = links[spec.grasp_link]
        self.mount_link = links[spec.camera_link or spec.grasp_link]
        self.link_names = {j: name for name, j in links.items()}
        self.hold = [(joints[n], *hold_target(q, spec.hold_force)) for n, q in spec.hold_joints.items()]
        closed = np.array([f.closed for f in spec.fingers])
        # Position = closed + scale x width, per finger joint (scale < 0 for a finger that opens
        # towards negative angles).
        opened = np.array([f.open for f in spec.fingers])
        self._closed, self._scale = closed, (opened - closed) / spec.max_finger_width
        infos = [c.getJointInfo(self.body, j) for j in self.arm]
        self.lower = np.array([i[8] for i in infos])
        self.upper = np.array([i[9] for i in infos])
        self.max_torque = np.array(spec.max_torque) if spec.max_torque else np.array([i[10] for i in infos])
        self.movable = self.arm + self.fingers
        # Every joint with a degree of freedom, in index order: what IK returns and inverse dynamics reads.
        self._dofs = [
            j
            for j in range(c.getNumJoints(self.body))
            if c.getJointInfo(self.body, j)[2] != pybullet.JOINT_FIXED
        ]
        self._arm_in_dofs = [self._dofs.index(j) for j in self.arm]
        self._offset = np.array(spec.grasp_offset, dtype=float)

    def _tie_mimic_joints(self, joints: dict[str, int]) -> None:
        """A gear constraint per mimic finger joint (at the ratio of the two joints' ranges), and no
        motor of its own: its velocity motor would hold it against the constraint."""
        by_name = {f.joint: f for f in self.spec.fingers}
        mimics = [f for f in self.spec.fingers if f.mimic]
        for f in mimics:
            lead = by_name[f.mimic]
            ratio = (f.open - f.closed) / (lead.open - lead.closed)
            tie = self.client.createConstraint(
                self.body,
                joints[f.mimic],
                self.body,
                joints[f.joint],
                pybullet.JOINT_GEAR,
                [1, 0, 0],
                [0, 0, 0],
                [0, 0, 0],
            )
            self.client.changeConstraint(tie, gearRatio=-ratio, maxForce=self.spec.hold_force, erp=1.0)
        if mimics:
            self.client.setJointMotorControlArray(
                self.body,
                [joints[f.joint] for f in mimics],
                pybullet.VELOCITY_CONTROL,
                forces=[0.0] * len(mimics),
            )
        self._driven = [i for i, f in enumerate(self.spec.fingers) if not f.mimic]

    # --- state ---------------------------------------------------------------------------------
    def finger_positions(self, width: float) -> list[float]:
        return [float(q) for q in self._closed + self._scale * width]

    def reset(self, arm_q: Sequence[float], finger_width: float | None = None) -> None:
        width = self.max_finger_width if finger_width is None else finger_width
        for j, q in zip(self.arm, arm_q):
            self.client.resetJointState(self.body, j, q)
        for j, q in zip(self.fingers, self.finger_positions(width)):
            self.client.resetJointState(self.body, j, q)
        for j, q, _ in self.hold:
            self.client.resetJointState(self.body, j, q)

    def joint_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        states = self.client.getJointStates(self.body, self.movable)
        q = np.array([s[0] for s in states])
        qd = np.array([s[1] for s in states])
        n = len(self.arm)
        widths = (q[n:] - self._closed) / self._scale
        return q[:n], qd[:n], float(sum(widths) / len(widths))

    def grasp_point(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.client.getLinkState(
            self.body, self.grasp_link, computeLinkVelocity=1, computeForwardKinematics=1
        )
        if not self._offset.any():
            return np.array(state[4]), np.array(state[6])
        arm = np.array(self.client.getMatrixFromQuaternion(state[5])).reshape(3, 3) @ self._offset
        return np.array(state[4]) + arm, np.array(state[6]) + np.cross(state[7], arm)

    def wrist_links(self) -> list[int]:
        return [j for j, name in self.link_names.items() if name in self.wrist_names]

    def camera_mount(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.client.getLinkState(self.body, self.mount_link, computeForwardKinematics=1)
        return np.array(state[4]), np.array(state[5])

    # --- dynamics ------------------------------------------------------------------------------
    def set_dynamics(self, joint_damping: float, finger_friction: float) -> None:
        for j in self.arm:
            self.client.changeDynamics(self.body, j, jointDamping=joint_damping)
        for link in self.finger_links:
            friction = finger_friction * self.spec.finger_friction_scale
            self.client.changeDynamics(self.body, link, lateralFriction=friction)

    # --- control -------------------------------------------------------------------------------
    def use_position_control(self, gain_scale: float = 1.0, finger_force: float = 20.0) -> None:
        self.position_gain = self.spec.position_gain * gain_scale
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
        force = self.finger_force * self.spec.finger_force_scale
        driven = self._driven
        targets = self.finger_positions(float(np.clip(width, 0.0, self.max_finger_width)))
        self.client.setJointMotorControlArray(
            self.body,
            [self.fingers[i] for i in driven],
            pybullet.POSITION_CONTROL,
            targetPositions=[targets[i] for i in driven],
            forces=[force] * len(driven),
        )
        if self.hold:
            self.client.setJointMotorControlArray(
                self.body,
                [j for j, _, _ in self.hold],
                pybullet.POSITION_CONTROL,
                targetPositions=[q for _, q, _ in self.hold],
                forces=[f for _, _, f in self.hold],
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
        states = self.client.getJointStates(self.body, self._dofs)
        q = [s[0] for s in states]
        zeros = [0.0] * len(q)
        tau = self.client.calculateInverseDynamics(self.body, q, zeros, zeros)
        return np.array(tau)[self._arm_in_dofs]

    def inverse_kinematics(self, position: np.ndarray, orientation=None) -> np.ndarray:
        orientation = self.gripper_down() if orientation is None else orientation
        if self._offset.any():  # aim the link so that the fixed frame lands on the target
            rotation = np.array(self.client.getMatrixFromQuaternion(orientation)).reshape(3, 3)
            position = np.asarray(position) - rotation @ self._offset
        q = self.client.calculateInverseKinematics(
            self.body,
            self.grasp_link,
            position,
            orientation,
            maxNumIterations=self.spec.ik_iterations,
        )
        return np.clip(np.array(q)[self._arm_in_dofs], self.lower, self.upper)


def hold_target(value: Any, default_force: float) -> tuple[float, float]:
    """A hold joint's (angle, motor force) from ``angle`` or ``[angle, force]``."""
    if isinstance(value, (int, float)):
        return float(value), float(default_force)
    angle, force = value
    return float(angle), float(force)


class Panda(ArmRobot):
    """The Franka Panda of ``pybullet_data``; a subclass may set its own ``neutral_pose``."""

    def __init__(
        self,
        client: BulletClient,
        urdf: str | None = None,
        render: str | None = None,
        collision: str = "mesh",
    ):
        super().__init__(builtin_spec("panda"), client, urdf, render, collision)
