"""An arm with a gripper, described by data: ``RobotSpec`` and the arms rlgrasp ships.

A spec names everything the generic ``rlgrasp.envs.robot.ArmRobot`` needs from a model file (URDF
or SDF): the arm joints, the grasp point, the finger joints and how their positions map to an
opening width, the neutral pose, gains and the wrist camera's mount. A user's arm is the same data
as a mapping (``robot={model: /my/arm.urdf, arm_joints: [...], ...}``): ``spec_from_mapping``
refuses an unknown key or a value of the wrong shape in one line naming the key; what needs the
model itself (names, limits, a gripper that opens) is checked when the arm is loaded. Figures of
each arm's scripted expert: docs/robots.md.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any


@dataclass(frozen=True)
class FingerJoint:
    """One gripper joint and its positions at the closed (width 0) and widest opening; positions in
    between are linear in the width. Mimic and linkage joints are listed too, since PyBullet does
    not enforce URDF mimic joints: with ``mimic`` (another finger joint's name) a joint follows that
    one through a gear constraint instead of a motor of its own, which keeps a linkage gripper's
    pads parallel when the object stops the drive."""

    joint: str
    open: float
    closed: float = 0.0
    mimic: str = ""


@dataclass(frozen=True)
class RobotSpec:
    """Everything an ``ArmRobot`` reads; keys as in the YAML of a user's arm (docs/robots.md)."""

    model: str  # a URDF or SDF file: an absolute path or a pybullet_data name
    arm_joints: tuple[str, ...]
    grasp_link: str  # the link the grasp point is fixed to
    fingers: tuple[FingerJoint, ...]
    finger_links: tuple[str, str]  # both must touch the object for a grasp
    neutral_pose: tuple[float, ...]  # rad, one per arm joint
    max_finger_width: float  # m between the fingers at the widest opening
    name: str = ""  # empty: the model file's stem
    #: A fixed frame in ``grasp_link``'s frame (m): the point between the fingertips when the model
    #: has no link there.
    grasp_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Euler angles (rad) of ``grasp_link`` when the fingers point down and close along world y.
    gripper_down: tuple[float, float, float] = (math.pi, 0.0, 0.0)
    base_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_orientation: tuple[float, float, float] = (0.0, 0.0, 0.0)  # Euler, rad
    #: Passive joints of the gripper held at an angle by a position motor (a wrist joint with no
    #: effort, fingertip joints), by name: the angle, or [angle, motor force] (a weak motor lets a
    #: fingertip comply with the object's face).
    hold_joints: Mapping[str, Any] = field(default_factory=dict)
    hold_force: float = 100.0  # N m (or N): the motor force of a hold joint given by its angle alone
    position_gain: float = 0.2  # the arm's position-control gain at gain scale 1
    #: Finger motor force (N, or N m for a revolute finger) per N of the episode's ``finger_force``.
    finger_force_scale: float = 1.0
    ik_iterations: int = 20
    #: null: the model's effort limits; otherwise one value per arm joint.
    max_torque: tuple[float, ...] | None = None
    camera_link: str = ""  # a wrist camera's mount (its z axis along the fingers); empty: grasp_link
    wrist_links: tuple[str, ...] = ()  # what a wrist camera can see; empty: the finger links
    #: A low-poly render model: (visual mesh folder, collision mesh folder) rewritten in the URDF;
    #: null: cameras render the model as it is.
    low_poly_meshes: tuple[str, str] | None = None
    #: Whether joint torques are a meaningful action: false for a model whose masses and inertias
    #: are placeholders (control_mode=joint_torque is then refused).
    torque_control: bool = True

    @property
    def label(self) -> str:
        return self.name or os.path.splitext(os.path.basename(self.model))[0]

    def as_mapping(self) -> dict[str, Any]:
        """The spec as the YAML of a user's arm would write it."""
        out = asdict(self)
        out["fingers"] = [asdict(f) for f in self.fingers]
        return out


_TUPLES = {"arm_joints", "finger_links", "neutral_pose", "grasp_offset", "gripper_down", "base_position",
           "base_orientation", "max_torque", "wrist_links", "low_poly_meshes"}
_LENGTHS = {"finger_links": 2, "grasp_offset": 3, "gripper_down": 3, "base_position": 3,
            "base_orientation": 3, "low_poly_meshes": 2}
def _required() -> list[str]:
    return [f.name for f in fields(RobotSpec) if f.default is MISSING and f.default_factory is MISSING]


def spec_from_mapping(mapping: Mapping[str, Any]) -> RobotSpec:
    """A user's arm; ``ValueError`` naming the first missing, unknown or badly shaped key."""
    known = [f.name for f in fields(RobotSpec)]
    data = dict(mapping)
    unknown = [k for k in data if k not in known]
    if unknown:
        raise ValueError(f"robot.{unknown[0]}: unknown key; a robot has {', '.join(known)}")
    missing = [k for k in _required() if k not in data]
    if missing:
        raise ValueError(f"robot.{missing[0]}: missing; a robot needs {', '.join(_required())}")
    for key in _TUPLES & set(data):
        value = data[key]
        if value is None and key in ("max_torque", "low_poly_meshes"):
            continue
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
            raise ValueError(f"robot.{key}={value!r}: must be a list")
        data[key] = tuple(value)
        if key in _LENGTHS and len(data[key]) != _LENGTHS[key]:
            raise ValueError(f"robot.{key}={list(value)!r}: must have {_LENGTHS[key]} entries")
    data["fingers"] = _fingers(data["fingers"])
    data["hold_joints"] = dict(data.get("hold_joints") or {})
    for key in ("neutral_pose", "grasp_offset", "gripper_down", "base_position", "base_orientation"):
        if key in data and not all(_number(v) for v in data[key]):
            raise ValueError(f"robot.{key}={list(data[key])!r}: must be numbers")
    if not (_number(data["max_finger_width"]) and data["max_finger_width"] > 0):
        raise ValueError(f"robot.max_finger_width={data['max_finger_width']!r}: must be a number > 0")
    return RobotSpec(**data)


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _fingers(value: Any) -> tuple[FingerJoint, ...]:
    """``[{joint, open, closed}, ...]``; ``ValueError`` naming the entry that is not one."""
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence) or not value:
        raise ValueError(f"robot.fingers={value!r}: must be a non-empty list of {{joint, open, closed}}")
    out = []
    for i, entry in enumerate(value):
        if isinstance(entry, FingerJoint):
            out.append(entry)
            continue
        keys = {"joint", "open", "closed", "mimic"}
        ok = isinstance(entry, Mapping) and set(entry) <= keys and "joint" in entry
        ok = ok and "open" in entry and all(_number(entry[k]) for k in ("open", "closed") if k in entry)
        if not ok:
            raise ValueError(f"robot.fingers[{i}]={entry!r}: must be {{joint: <name>, open: <position>, "
                             "closed: <position>[, mimic: <finger joint>]}")
        out.append(FingerJoint(str(entry["joint"]), float(entry["open"]), float(entry.get("closed", 0.0)),
                               str(entry.get("mimic") or "")))
    return tuple(out)


# --- the arms rlgrasp ships (configs/robot/<name>.yaml selects one) -----------------------------
PANDA = RobotSpec(
    name="panda",
    model="franka_panda/panda.urdf",
    arm_joints=tuple(f"panda_joint{i}" for i in range(1, 8)),
    grasp_link="panda_grasptarget",  # a fixed link of the Panda URDF between the fingertips
    fingers=(FingerJoint("panda_finger_joint1", 0.04), FingerJoint("panda_finger_joint2", 0.04)),
    finger_links=("panda_leftfinger", "panda_rightfinger"),
    neutral_pose=(0.0, 0.41, 0.0, -1.85, 0.0, 2.26, 0.79),
    max_finger_width=0.08,
    position_gain=0.2,  # twice PyBullet's default: the grasp point keeps up with 4 cm steps
    ik_iterations=20,  # fewer lag behind when reaching out along x; converged solves exit early
    camera_link="panda_hand",
    wrist_links=("panda_hand", "panda_leftfinger", "panda_rightfinger", "panda_grasptarget"),
    low_poly_meshes=("meshes/visual/", "meshes/collision/"),
)

KUKA_IIWA = RobotSpec(
    name="kuka_iiwa",
    model="kuka_iiwa/kuka_with_gripper2.sdf",
    arm_joints=tuple(f"J{i}" for i in range(7)),
    grasp_link="lbr_iiwa_link_7",
    grasp_offset=(0.0, 0.0215, 0.28),
    fingers=(FingerJoint("base_left_finger_joint", -0.3), FingerJoint("base_right_finger_joint", 0.3)),
    finger_links=("left_finger_tip", "right_finger_tip"),
    neutral_pose=(-0.195, 0.646, 0.319, -1.299, -0.201, 1.228, -1.44),  # IK: grasp point at (0.6, 0, 0.2)
    max_finger_width=0.1,
    gripper_down=(0.0, math.pi, math.pi / 2),
    base_position=(-0.1, 0.0, 0.07),
    # The wrist joint is stiff; the fingertips comply (2 N m, as pybullet_envs' Kuka does) and lie
    # flat on the object's faces instead of wedging it out of the grip.
    hold_joints={"gripper_to_arm": 0.0, "left_base_tip_joint": [0.0, 2.0],
                 "right_base_tip_joint": [0.0, 2.0]},
    finger_force_scale=0.3,  # N m per N: 3-12 N m for the `default` finger forces of 10-40 N
    camera_link="base_link",
)

XARM6 = RobotSpec(
    name="xarm6",
    model="xarm/xarm6_with_gripper.urdf",
    arm_joints=tuple(f"joint{i}" for i in range(1, 7)),
    grasp_link="xarm_gripper_base_link",
    grasp_offset=(0.0, 0.0, 0.17),
    # One motor on the drive joint; the linkage's five other joints follow it (gear constraints).
    fingers=(FingerJoint("drive_joint", 0.0, 0.85), *(
        FingerJoint(j, 0.0, 0.85, mimic="drive_joint") for j in (
            "left_finger_joint", "left_inner_knuckle_joint", "right_outer_knuckle_joint",
            "right_finger_joint", "right_inner_knuckle_joint"))),
    finger_links=("left_finger", "right_finger"),
    neutral_pose=(0.0, 0.449, -1.701, 0.0, 1.251, 0.0),  # IK: grasp point at (0.6, 0, 0.2)
    max_finger_width=0.085,
    # The drive joint's torque reaches the pads through a ~5 cm lever: 0.6 N m per 20 N keeps the
    # pad force near a parallel gripper's; a full 20 N m squeezes the cube out of the grip.
    finger_force_scale=0.03,
    base_position=(0.0, 0.0, 0.0),
    camera_link="xarm_gripper_base_link",
)
