"""Which arm an env drives: ``ROBOTS`` (the arms rlgrasp ships, by name) and ``make_robot``.

An arm is data (``rlgrasp.envs.robot_spec.RobotSpec``) loaded by the generic
``rlgrasp.envs.arm.ArmRobot``; the env's ``robot`` keyword is a name of ``ROBOTS`` or a user's
arm as a mapping of the spec's keys (docs/robots.md). A ``Robot`` subclass registered under a name
is built as it is.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.arm import ArmRobot, Panda, low_poly_urdf
from rlgrasp.envs.robot_base import GRIPPER_DOWN, Robot
from rlgrasp.envs.robot_spec import BUILTIN_ROBOTS, RobotSpec, builtin_spec, spec_from_mapping

__all__ = [
    "GRIPPER_DOWN",
    "ROBOTS",
    "ArmRobot",
    "Panda",
    "Robot",
    "low_poly_urdf",
    "make_robot",
    "resolve_robot",
    "robot_label",
]

#: ``env.robot`` names -> the arm's spec (or a ``Robot`` class, built with ``(client, model, render)``);
#: the built-in arms' specs are read from ``rlgrasp/envs/robots/<name>.yaml``.
ROBOTS: dict[str, RobotSpec | type[Robot]] = {name: builtin_spec(name) for name in BUILTIN_ROBOTS}


def resolve_robot(robot: str | Mapping[str, Any] | RobotSpec) -> RobotSpec | type[Robot]:
    """A name of ``ROBOTS``, a spec, or a user's arm as a mapping; ``ValueError`` naming what is wrong."""
    if isinstance(robot, RobotSpec):
        return robot
    if isinstance(robot, Mapping):
        return spec_from_mapping(robot)
    if not isinstance(robot, str) or robot not in ROBOTS:
        raise ValueError(
            f"unknown robot {robot!r}; valid robots: {', '.join(ROBOTS)} or a mapping "
            "{model: ..., arm_joints: [...], ...} (docs/robots.md)"
        )
    return ROBOTS[robot]


def robot_label(robot: Any) -> str:
    """The arm's name as a checkpoint and an error message show it: a ``ROBOTS`` name, or a user's
    arm's ``name`` (else its model file's stem)."""
    if isinstance(robot, str):
        return robot
    if isinstance(robot, Mapping):
        name = str(robot.get("name") or "").strip()
        return name or os.path.splitext(os.path.basename(str(robot.get("model"))))[0]
    if isinstance(robot, RobotSpec):
        return robot.label
    return "panda" if robot is None else str(robot)


def make_robot(
    name: str | Mapping[str, Any] | RobotSpec,
    client: BulletClient,
    model: str | None = None,
    render: str | None = None,
    collision: str = "mesh",
) -> Robot:
    """The arm ``name`` (see ``resolve_robot``; ``{name: panda, model: ...}`` is a registered arm with
    another model file); ``model`` overrides its model file (a path or a pybullet_data name);
    ``render`` asks for the model cameras render cheaply (``low_poly``, or ``wrist``: only what a
    wrist camera sees); ``collision`` for its collision shapes (``rlgrasp.envs.collision_model``)."""
    if isinstance(name, Mapping) and set(name) <= {"name", "model"} and "name" in name:
        name, model = name["name"], name.get("model") or model  # a registered arm, another model file
    arm = resolve_robot(name)
    if isinstance(arm, RobotSpec):
        return ArmRobot(arm, client, model, render=render, collision=collision)
    if collision != "mesh":  # a registered class may not take the keyword
        return arm(client, model, render=render, collision=collision)
    return arm(client, model, render=render)
