"""An arm with a gripper, described by data: ``RobotSpec``, and the arms rlgrasp ships as such data.

A spec names everything the generic ``rlgrasp.envs.robot.ArmRobot`` needs from a model file (URDF
or SDF): the arm joints, the grasp point, the finger joints and how their positions map to an
opening width, the neutral pose, gains and the wrist camera's mount. A user's arm is the same data
as a mapping (``robot={model: /my/arm.urdf, arm_joints: [...], ...}``): ``spec_from_mapping``
refuses an unknown key or a value of the wrong shape in one line naming the key; what needs the
model itself (names, limits, a gripper that opens) is checked when the arm is loaded. The built-in
arms are YAML files of the same format (``rlgrasp/envs/robots/<name>.yaml``, ``builtin_spec``).
Figures of each arm's scripted expert: docs/robots.md.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf


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
    #: Friction coefficient of the finger links per unit of the episode's ``finger_friction`` (PyBullet
    #: multiplies it by the object's): a rubber pad grips more than the default 1.
    finger_friction_scale: float = 1.0
    ik_iterations: int = 20
    #: null: the model's effort limits; otherwise one value per arm joint.
    max_torque: tuple[float, ...] | None = None
    camera_link: str = ""  # a wrist camera's mount (its z axis along the fingers); empty: grasp_link
    wrist_links: tuple[str, ...] = ()  # what a wrist camera can see; empty: the finger links
    #: The cheap model cameras render (``rlgrasp.envs.render_model``): [visual mesh folder, collision
    #: mesh folder] rewritten in the URDF, or ``boxes`` (the visual meshes of links outside
    #: ``wrist_links`` become their bounding boxes); null: cameras render the model as it is.
    low_poly_meshes: tuple[str, str] | str | None = None
    #: Whether joint torques are a meaningful action: false for a model whose masses and inertias
    #: are placeholders (control_mode=joint_torque is then refused).
    torque_control: bool = True
    #: The scripted expert's grasp for this gripper (``rlgrasp.envs.robot_spec.EXPERT_KEYS``): where the
    #: grasp point goes on the object, e.g. ``{finger_reach: 0.055, floor_clearance: 0.006}`` for
    #: fingertips that end at the grasp point; empty: the defaults, tuned on the Panda.
    expert: Mapping[str, float] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return self.name or os.path.splitext(os.path.basename(self.model))[0]

    def as_mapping(self) -> dict[str, Any]:
        """The spec as the YAML of a user's arm would write it."""
        out = asdict(self)
        out["fingers"] = [asdict(f) for f in self.fingers]
        out["expert"] = dict(self.expert)
        return out


_TUPLES = {
    "arm_joints",
    "finger_links",
    "neutral_pose",
    "grasp_offset",
    "gripper_down",
    "base_position",
    "base_orientation",
    "max_torque",
    "wrist_links",
    "low_poly_meshes",
}
_LENGTHS = {
    "finger_links": 2,
    "grasp_offset": 3,
    "gripper_down": 3,
    "base_position": 3,
    "base_orientation": 3,
    "low_poly_meshes": 2,
}


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
        if key == "low_poly_meshes" and isinstance(value, str):
            if value != "boxes":
                raise ValueError(
                    f"robot.low_poly_meshes={value!r}: must be null, boxes or [visual mesh "
                    "folder, collision mesh folder]"
                )
            continue
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
            raise ValueError(f"robot.{key}={value!r}: must be a list")
        data[key] = tuple(value)
        if key in _LENGTHS and len(data[key]) != _LENGTHS[key]:
            raise ValueError(f"robot.{key}={list(value)!r}: must have {_LENGTHS[key]} entries")
    data["fingers"] = _fingers(data["fingers"])
    data["hold_joints"] = dict(data.get("hold_joints") or {})
    data["expert"] = _expert(data.get("expert"))
    for key in ("neutral_pose", "grasp_offset", "gripper_down", "base_position", "base_orientation"):
        if key in data and not all(_number(v) for v in data[key]):
            raise ValueError(f"robot.{key}={list(data[key])!r}: must be numbers")
    for key in ("finger_force_scale", "finger_friction_scale"):
        if key in data and not (_number(data[key]) and data[key] > 0):
            raise ValueError(f"robot.{key}={data[key]!r}: must be a number > 0")
    if not (_number(data["max_finger_width"]) and data["max_finger_width"] > 0):
        raise ValueError(f"robot.max_finger_width={data['max_finger_width']!r}: must be a number > 0")
    return RobotSpec(**data)


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


#: The scripted expert's settings an arm may set, with the values each allows (m): how far below
#: the object's top the grasp point goes, how far above its bottom at least, and how high above
#: the grasp height the hand turns before it descends.
EXPERT_KEYS = {"finger_reach": (0.0, 0.2), "floor_clearance": (0.0, 0.1), "hover": (0.01, 0.2)}


def _expert(value: Any) -> dict[str, float]:
    """``{finger_reach: m, floor_clearance: m, hover: m}``, any subset; ``ValueError`` naming the key."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(f"robot.expert={value!r}: must be a mapping of {', '.join(EXPERT_KEYS)} (m)")
    out = {}
    for key, v in value.items():
        if key not in EXPERT_KEYS:
            raise ValueError(
                f"robot.expert.{key}: unknown key; the expert's settings: {', '.join(EXPERT_KEYS)}"
            )
        low, high = EXPERT_KEYS[key]
        if not (_number(v) and low <= v <= high):
            raise ValueError(f"robot.expert.{key}={v!r}: must be a number of metres in [{low}, {high}]")
        out[str(key)] = float(v)
    return out


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
            raise ValueError(
                f"robot.fingers[{i}]={entry!r}: must be {{joint: <name>, open: <position>, "
                "closed: <position>[, mimic: <finger joint>]}"
            )
        out.append(
            FingerJoint(
                str(entry["joint"]),
                float(entry["open"]),
                float(entry.get("closed", 0.0)),
                str(entry.get("mimic") or ""),
            )
        )
    return tuple(out)


# --- the arms rlgrasp ships: rlgrasp/envs/robots/<name>.yaml, files of a user's arm's format ----
#: Where the built-in arms' descriptions live (package data: pyproject.toml ships them).
BUILTIN_DIR = Path(__file__).with_name("robots")
#: The built-in arms, the default first (configs/robot/<name>.yaml selects one by name).
BUILTIN_ROBOTS = ("panda", "kuka_iiwa", "xarm6")


@functools.cache
def builtin_spec(name: str) -> RobotSpec:
    """A built-in arm's spec, read from its YAML file as a user's ``configs/robot/<arm>.yaml`` is."""
    return spec_from_file(BUILTIN_DIR / f"{name}.yaml")


def spec_from_file(path: str | os.PathLike) -> RobotSpec:
    """The arm of a YAML file holding ``robot: {model: ..., ...}`` (a ``robot`` config group file)."""
    node = OmegaConf.to_container(OmegaConf.load(path), resolve=True)
    if not isinstance(node, Mapping) or not isinstance(node.get("robot"), Mapping):
        raise ValueError(f"{path}: must hold a mapping `robot: {{model: ..., arm_joints: [...], ...}}`")
    return spec_from_mapping(node["robot"])
