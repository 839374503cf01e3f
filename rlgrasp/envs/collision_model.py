"""Which collision shapes an arm's links get: the model's own meshes, or primitive shapes.

``collision_model="mesh"`` (the default) loads the model as it is. ``"primitive"`` replaces the
collision meshes of the links that touch the object (the Panda's hand and fingers) with boxes and
capsules, written as a URDF variant beside the original in the temp directory. Bullet collides
boxes with its box-box routine instead of running GJK over each mesh's vertices; the links move and
weigh as before (their inertials, joints and contact parameters are untouched).

The variant is opt-in because it changes the contacts, and so the episodes: a policy trained on
the meshes (every policy in ``policies/``) is evaluated on the meshes. PyBullet computes a link's
inertia from its collision shapes (the URDF's tensor is read only with a flag rlgrasp does not
pass), so ``keep_mesh_inertia`` gives the replaced links the inertia the mesh model has: only the
contact geometry differs.

The Panda's shapes follow the convex hulls of ``meshes/collision/finger.obj`` and ``hand.obj``
(PyBullet collides a URDF mesh as its convex hull), in each link's own frame: the finger as a pad
(inner face, tip) and a base block; the hand as a palm box and a capsule across its width for the
rounded top. Each box is 1 mm larger on every side than the hull it stands for, because PyBullet
adds its 1 mm collision margin around a hull but inside a box.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import pybullet
from pybullet_utils.bullet_client import BulletClient

COLLISION_MODELS = ("mesh", "primitive")
MARGIN = 0.001  # PyBullet's URDF collision margin: around a hull, inside a box


@dataclass(frozen=True)
class Box:
    """A box from its lower and upper corner in the link frame (the hull's extent there)."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]

    def urdf(self) -> str:
        centre = " ".join(f"{(a + b) / 2:.6g}" for a, b in zip(self.low, self.high))
        size = " ".join(f"{b - a + 2 * MARGIN:.6g}" for a, b in zip(self.low, self.high))
        return (
            f'<collision><origin xyz="{centre}" rpy="0 0 0"/>'
            f'<geometry><box size="{size}"/></geometry></collision>'
        )


@dataclass(frozen=True)
class Capsule:
    """A capsule (``length`` between its end centres) at ``xyz``, its axis turned by ``rpy`` from z."""

    radius: float
    length: float
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def urdf(self) -> str:
        xyz, rpy = (" ".join(f"{v:.6g}" for v in t) for t in (self.xyz, self.rpy))
        return (
            f'<collision><origin xyz="{xyz}" rpy="{rpy}"/><geometry>'
            f'<capsule radius="{self.radius:.6g}" length="{self.length:.6g}"/></geometry></collision>'
        )


def _finger(side: float) -> tuple[Box, ...]:
    """The Panda finger (``side`` +1 left, -1 right: the right one is the left turned about z)."""

    def box(low, high):
        ys = sorted((side * low[1], side * high[1]))
        return Box((low[0], ys[0], low[2]), (high[0], ys[1], high[2]))

    return (
        box((-0.0095, 0.0, 0.019), (0.0095, 0.0142, 0.0538)),  # the pad: inner face and tip
        box((-0.0105, 0.002, 0.0), (0.0105, 0.0264, 0.019)),  # the base block at the hand
    )


#: Per arm (``RobotSpec.name``): the links given primitive shapes, and their shapes.
PRIMITIVES: dict[str, dict[str, tuple[Box | Capsule, ...]]] = {
    "panda": {
        "panda_hand": (
            Box((-0.0175, -0.1, 0.0), (0.0175, 0.1, 0.066)),  # the palm, down to the finger slots
            Capsule(0.0316, 0.14, (0.0, 0.0, 0.004), (1.5707963267948966, 0.0, 0.0)),  # the rounded top
        ),
        "panda_leftfinger": _finger(1.0),
        "panda_rightfinger": _finger(-1.0),
    },
}


def collision_variant(path: str, robot: str, model: str) -> str:
    """The model file to load for ``model`` (a name of ``COLLISION_MODELS``): ``path`` itself for
    ``mesh``, else the primitive URDF variant of arm ``robot``."""
    if model not in COLLISION_MODELS:
        raise ValueError(f"unknown collision_model {model!r}; valid: {', '.join(COLLISION_MODELS)}")
    if model == "mesh":
        return path
    if robot not in PRIMITIVES:
        raise ValueError(
            f"collision_model=primitive: no primitive shapes for robot {robot!r}; "
            f"arms that have them: {', '.join(PRIMITIVES)}"
        )
    if not path.lower().endswith(".urdf"):
        raise ValueError(f"collision_model=primitive: {path!r} is not a URDF")
    return primitive_urdf(path, PRIMITIVES[robot])


def primitive_urdf(path: str, shapes: Mapping[str, Sequence[Box | Capsule]]) -> str:
    """The URDF at ``path`` with each named link's collision elements replaced by ``shapes``
    (mesh paths made absolute); ``ValueError`` naming a link the file does not have."""
    text = open(path).read().replace("package://", os.path.dirname(path) + os.sep)
    for link, parts in shapes.items():
        found = re.search(rf'<link\s+name="{re.escape(link)}"\s*>(.*?)</link>', text, flags=re.S)
        if found is None:
            raise ValueError(f"collision_model=primitive: link {link!r} not found in {path}")
        body = re.sub(r"\s*<collision>.*?</collision>", "", found.group(1), flags=re.S)
        body += "".join(part.urdf() for part in parts) + "\n"
        text = text[: found.start(1)] + body + text[found.end(1) :]
    return write_once(text, "rlgrasp-primitive")


def keep_mesh_inertia(client: BulletClient, body: int, mesh_path: str, robot: str, model: str) -> None:
    """Give the links whose shapes ``model`` replaced the inertia they have in the model at
    ``mesh_path`` (nothing to do for ``mesh``)."""
    if model == "mesh":
        return
    inertia = _mesh_inertia(mesh_path, tuple(PRIMITIVES[robot]))
    for j in range(client.getNumJoints(body)):
        name = client.getJointInfo(body, j)[12].decode()
        if name in inertia:
            client.changeDynamics(body, j, localInertiaDiagonal=inertia[name])


_INERTIA: dict[tuple[str, tuple[str, ...]], dict[str, tuple[float, float, float]]] = {}


def _mesh_inertia(path: str, links: tuple[str, ...]) -> dict[str, tuple[float, float, float]]:
    """Each link's local inertia diagonal as PyBullet computes it for the model at ``path``, read
    once per process in a private client."""
    if (path, links) not in _INERTIA:
        client = BulletClient(pybullet.DIRECT)
        try:
            body = client.loadURDF(path, useFixedBase=True)
            infos = {client.getJointInfo(body, j)[12].decode(): j for j in range(client.getNumJoints(body))}
            _INERTIA[path, links] = {n: client.getDynamicsInfo(body, infos[n])[2] for n in links}
        finally:
            client.disconnect()
    return _INERTIA[path, links]


def write_once(text: str, prefix: str) -> str:
    """``text`` as a URDF in the temp directory, named by its digest: written once per machine,
    atomically, since several workers may ask at once."""
    digest = hashlib.sha1(text.encode()).hexdigest()[:12]
    target = os.path.join(tempfile.gettempdir(), f"{prefix}-{digest}.urdf")
    if not os.path.isfile(target):
        fd, scratch = tempfile.mkstemp(suffix=".urdf", dir=tempfile.gettempdir())
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(scratch, target)
    return target
