"""Checks of a robot description against itself and against its loaded model: a user's arm fails
when the env is built, in one line naming the key and what is allowed, never deep in an episode."""

from __future__ import annotations

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.robot_spec import RobotSpec

#: The fingers must move apart by at least this much (m) from closed to open.
MIN_OPENING = 0.005
#: Joint limits are compared with this slack (rad or m): a pose exactly on a limit is inside.
LIMIT_SLACK = 1e-6


def check_spec_values(spec: RobotSpec) -> None:
    """What needs no model: sizes that must agree with each other."""
    n = len(spec.arm_joints)
    if n == 0:
        raise ValueError("robot.arm_joints=[]: must name at least one joint")
    if len(spec.neutral_pose) != n:
        raise ValueError(
            f"robot.neutral_pose has {len(spec.neutral_pose)} angles: must have one per arm "
            f"joint ({n}: {', '.join(spec.arm_joints)})"
        )
    if spec.max_torque is not None and len(spec.max_torque) != n:
        raise ValueError(
            f"robot.max_torque has {len(spec.max_torque)} values: must be null or one per arm joint ({n})"
        )
    if len(spec.finger_links) != 2:
        raise ValueError(f"robot.finger_links={list(spec.finger_links)!r}: must name two links (left, right)")


def _joint_name(client: BulletClient, body: int, j: int) -> str:
    return client.getJointInfo(body, j)[1].decode()


def check_model(
    spec: RobotSpec, client: BulletClient, body: int, joints: dict[str, int], links: dict[str, int], path: str
) -> None:
    """Names the spec uses exist in the model, the neutral pose is inside the limits, the fingers open."""
    movable = [n for n, j in joints.items() if client.getJointInfo(body, j)[2] != pybullet.JOINT_FIXED]
    names = {
        "arm_joints": list(spec.arm_joints),
        "fingers": [f.joint for f in spec.fingers],
        "hold_joints": list(spec.hold_joints),
    }
    _require(names, movable, "a movable joint", path)
    link_keys = {
        "grasp_link": [spec.grasp_link],
        "finger_links": list(spec.finger_links),
        "camera_link": [spec.camera_link] if spec.camera_link else [],
        "wrist_links": list(spec.wrist_links),
    }
    _require(link_keys, list(links), "a link", path)
    driven = [f.joint for f in spec.fingers if not f.mimic]
    for f in spec.fingers:
        if f.mimic and f.mimic not in driven:
            raise ValueError(
                f"robot.fingers: {f.joint} mimics {f.mimic!r}, which must be a finger joint "
                f"with a motor of its own: {', '.join(driven) or 'none is'}"
            )
    _check_neutral_pose(spec, client, body, [joints[n] for n in spec.arm_joints])
    _check_fingers(spec, client, body, joints, links)


def _check_neutral_pose(spec: RobotSpec, client: BulletClient, body: int, arm: list[int]) -> None:
    for name, j, q in zip(spec.arm_joints, arm, spec.neutral_pose):
        low, high = client.getJointInfo(body, j)[8:10]
        if low <= high and not (low - LIMIT_SLACK <= q <= high + LIMIT_SLACK):
            raise ValueError(f"robot.neutral_pose: {name}={q} is outside its limits [{low}, {high}]")


def _check_fingers(
    spec: RobotSpec, client: BulletClient, body: int, joints: dict[str, int], links: dict[str, int]
) -> None:
    """Each finger position inside its joint's limits, and the finger links apart when open and
    together when closed (teleported, then put back: no physics step)."""
    for f in spec.fingers:
        low, high = client.getJointInfo(body, joints[f.joint])[8:10]
        for what, q in (("open", f.open), ("closed", f.closed)):
            if low <= high and not (low - LIMIT_SLACK <= q <= high + LIMIT_SLACK):
                raise ValueError(f"robot.fingers: {f.joint} {what}={q} is outside its limits [{low}, {high}]")
    gap = {}
    saved = [client.getJointState(body, joints[f.joint])[0] for f in spec.fingers]
    for what in ("open", "closed"):
        for f in spec.fingers:
            client.resetJointState(body, joints[f.joint], getattr(f, what))
        left, right = (
            client.getLinkState(body, links[n], computeForwardKinematics=1)[4] for n in spec.finger_links
        )
        gap[what] = float(np.linalg.norm(np.subtract(left, right)))
    for f, q in zip(spec.fingers, saved):
        client.resetJointState(body, joints[f.joint], q)
    if gap["open"] < gap["closed"] + MIN_OPENING:
        raise ValueError(
            f"robot.fingers: the finger links {', '.join(spec.finger_links)} are {gap['closed']:.3f} m "
            f"apart closed and {gap['open']:.3f} m open: open must part them by at least {MIN_OPENING} m "
            "(check the signs of open and closed)"
        )


def _require(wanted_by_key: dict[str, list[str]], available: list[str], what: str, path: str) -> None:
    """The first name the spec uses that the model lacks, named with its key and what the model has."""
    plural = {"a movable joint": "movable joints", "a link": "links"}[what]
    for key, wanted in wanted_by_key.items():
        for name in wanted:
            if name not in available:
                raise ValueError(
                    f"robot.{key}: {name!r} is not {what} of {path}; its {plural}: {', '.join(available)}"
                )
