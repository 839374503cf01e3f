"""The model cameras render of an arm: a copy of its URDF or SDF with cheaper visuals.

Rendering cost on the CPU follows the robot's visual triangles, and every visual shape costs a sync
per image even when transparent. Physics reads only the collision shapes, which the copy keeps as
they are, so the arm moves exactly as before. Two rules (``RobotSpec.low_poly_meshes``):

- ``[visual folder, collision folder]``: each visual mesh replaced by the collision mesh of the same
  name (the Panda, whose collision meshes are a low-poly copy of its visual ones);
- ``boxes``: each visual mesh of a link outside ``keep`` becomes its bounding box (the iiwa, whose
  collision meshes are its visual ones; the xArm6, whose gripper base alone has 24k triangles), while
  the gripper's links, which a wrist camera sees up close, keep their meshes.

With ``visible_links``, the other links lose their visuals altogether (a wrist camera never sees
them). The copy is written once per machine into the temp directory (mesh paths made absolute),
atomically: several workers may ask at once.
"""

from __future__ import annotations

import hashlib
import os
import re
import struct
import tempfile
from collections.abc import Sequence

import numpy as np
import pybullet

#: A link element of a URDF or an SDF (self-closing or not), its name in group 2.
_LINK = re.compile(r"<link\s+name=([\"'])([^\"']*)\1\s*(?:/>|>.*?</link>)", re.S)
_VISUAL = re.compile(r"<visual\b.*?</visual>", re.S)


def low_poly_urdf(path: str, meshes: tuple[str, str], visible_links: Sequence[str] | None = None) -> str:
    """The same URDF with each visual mesh replaced by its collision mesh (``meshes``: the visual and
    the collision mesh folders under ``package://``): the Panda's visual meshes make a 64x64 image
    cost ten times what its collision meshes do."""
    text = open(path).read()
    folder = os.path.dirname(path)
    visual, collision = meshes
    low = text.replace("package://" + visual, os.path.join(folder, collision))
    low = low.replace("package://", folder + os.sep)
    if visible_links is not None:
        low = _strip_visuals(low, visible_links)
    return _write_once(low, ".urdf")


def boxed_model(path: str, keep: Sequence[str], visible_links: Sequence[str] | None = None) -> str:
    """The same URDF or SDF with each visual mesh of a link outside ``keep`` replaced by its bounding
    box (12 triangles; a mesh the code cannot read stays as it is)."""
    text = open(path).read()
    folder = os.path.dirname(path)
    sdf = path.lower().endswith(".sdf")
    text = _absolute_mesh_paths(text, folder, sdf)

    def box_link(link: re.Match) -> str:
        if link.group(2) in keep:
            return link.group(0)
        return _VISUAL.sub(lambda v: _boxed_visual(v.group(0), sdf), link.group(0))

    low = _LINK.sub(box_link, text)
    if visible_links is not None:
        low = _strip_visuals(low, visible_links)
    return _write_once(low, ".sdf" if sdf else ".urdf")


def _strip_visuals(text: str, visible_links: Sequence[str]) -> str:
    def strip(link: re.Match) -> str:
        return link.group(0) if link.group(2) in visible_links else _VISUAL.sub("", link.group(0))

    return _LINK.sub(strip, text)


def _absolute_mesh_paths(text: str, folder: str, sdf: bool) -> str:
    """Mesh references that still resolve from the temp directory: ``package://`` and relative
    names (an SDF's ``/meshes/x.stl`` too, which PyBullet reads relative to the file) under ``folder``."""

    def absolute(name: str) -> str:
        name = name.removeprefix("package://")
        return name if os.path.isfile(name) else os.path.join(folder, name.lstrip("/"))

    if sdf:
        return re.sub(r"<uri>\s*(.*?)\s*</uri>", lambda m: f"<uri>{absolute(m.group(1))}</uri>", text)
    return re.sub(r'filename="([^"]*)"', lambda m: f'filename="{absolute(m.group(1))}"', text)


def _boxed_visual(visual: str, sdf: bool) -> str:
    """A ``<visual>`` whose mesh became its bounding box, the box's centre moved into the origin."""
    if sdf:
        mesh = re.search(r"<mesh>(.*?)</mesh>", visual, re.S)
        file = mesh and re.search(r"<uri>(.*?)</uri>", mesh.group(1))
        scale = mesh and re.search(r"<scale>(.*?)</scale>", mesh.group(1))
        pose = re.search(r"<pose>(.*?)</pose>", visual)
    else:
        mesh = re.search(r"<mesh\b[^>]*/>", visual)
        file = mesh and re.search(r'filename="([^"]*)"', mesh.group(0))
        scale = mesh and re.search(r'scale="([^"]*)"', mesh.group(0))
        pose = None
    bounds = mesh_bounds(file.group(1)) if file else None
    if bounds is None:
        return visual
    factor = np.array(scale.group(1).split(), float) if scale else np.ones(3)
    low, high = bounds[0] * factor, bounds[1] * factor
    low, high = np.minimum(low, high), np.maximum(low, high)  # a negative scale mirrors
    size, centre = high - low, (high + low) / 2
    xyz, rpy = _origin(visual, sdf, pose)
    rotation = np.array(pybullet.getMatrixFromQuaternion(pybullet.getQuaternionFromEuler(rpy))).reshape(3, 3)
    xyz = xyz + rotation @ centre
    numbers = " ".join
    if sdf:
        box = f"<box><size>{numbers(map(repr, size.tolist()))}</size></box>"
        origin = f"<pose>{numbers(map(repr, [*xyz.tolist(), *rpy]))}</pose>"
        out = re.sub(r"<pose>.*?</pose>", "", visual, count=1)
    else:
        box = f'<box size="{numbers(map(repr, size.tolist()))}"/>'
        origin = f'<origin xyz="{numbers(map(repr, xyz.tolist()))}" rpy="{numbers(map(repr, rpy))}"/>'
        out = re.sub(r"<origin\b[^>]*/>", "", visual, count=1)
    out = out.replace(mesh.group(0), box) if not sdf else out.replace(f"<mesh>{mesh.group(1)}</mesh>", box)
    return re.sub(r"(<visual\b[^>]*>)", lambda m: m.group(1) + origin, out, count=1)


def _origin(visual: str, sdf: bool, pose: re.Match | None) -> tuple[np.ndarray, list[float]]:
    if sdf:
        values = [float(v) for v in pose.group(1).split()] if pose else [0.0] * 6
        return np.array(values[:3]), values[3:6]
    origin = re.search(r"<origin\b[^>]*/>", visual)
    xyz = origin and re.search(r'xyz="([^"]*)"', origin.group(0))
    rpy = origin and re.search(r'rpy="([^"]*)"', origin.group(0))
    return (
        np.array(xyz.group(1).split(), float) if xyz else np.zeros(3),
        [float(v) for v in rpy.group(1).split()] if rpy else [0.0, 0.0, 0.0],
    )


def mesh_bounds(path: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The axis-aligned bounds of an OBJ or STL mesh's vertices in its own frame; None for another
    format or a file that cannot be read."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError:
        return None
    kind = os.path.splitext(path)[1].lower()
    if kind == ".obj":
        vertices = [
            line.split()[1:4] for line in data.decode(errors="replace").splitlines() if line.startswith("v ")
        ]
    elif kind == ".stl":
        vertices = _stl_vertices(data)
    else:
        return None
    if not len(vertices):
        return None
    points = np.asarray(vertices, float)
    return points.min(axis=0), points.max(axis=0)


def _stl_vertices(data: bytes) -> np.ndarray | list:
    """A binary STL's vertices (its header may start with ``solid`` too: the size decides), else an
    ASCII one's."""
    if len(data) >= 84:
        count = struct.unpack("<I", data[80:84])[0]
        if len(data) == 84 + 50 * count:
            records = np.frombuffer(
                data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), count, 84
            )
            return records["v"].reshape(-1, 3)
    return [
        line.split()[1:4]
        for line in data.decode(errors="replace").splitlines()
        if line.strip().startswith("vertex")
    ]


def _write_once(text: str, suffix: str) -> str:
    digest = hashlib.sha1(text.encode()).hexdigest()[:12]
    target = os.path.join(tempfile.gettempdir(), f"rlgrasp-lowpoly-{digest}{suffix}")
    if not os.path.isfile(target):
        fd, scratch = tempfile.mkstemp(suffix=suffix, dir=tempfile.gettempdir())
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(scratch, target)
    return target
