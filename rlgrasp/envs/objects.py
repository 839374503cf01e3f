"""Object sets: which bodies an episode can draw, and the geometry the env needs to place them.

``objects=`` on the env is plain data so it survives Hydra configs and pickling:

- a set name: ``"cube"`` (the default), ``"primitives"``, ``"random_urdfs"``,
  ``"random_urdfs_train"``, ``"random_urdfs_test"``, ``"toys"``;
- a list of set names: a mixture, each set drawn equally often;
- a mapping ``{"sets": [...], "paths": ["/my/meshes/*.obj", "dir/"], "max_width": 0.05,
  "scale": "fit"}``: user URDF/OBJ files (files, folders or globs) join the mixture as one group.

Held-out split of pybullet_data's ``random_urdfs/000-999``: ``random_urdfs_test`` is the 100
objects whose number ends in 0, ``random_urdfs_train`` the other 900 (the split
KukaDiverseObjectEnv uses); number 168 is never drawn, its mesh is broken. Mesh objects wider
than the hand are scaled down so that their smaller horizontal extent is at most ``max_width``;
every object's size is then multiplied by the episode's ``object_size_scale``, snapped to
``SIZE_SCALES`` so that the shapes built for it can be cached.
"""

from __future__ import annotations

import glob
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

SIZE_SCALES = (0.8, 0.9, 1.0, 1.1, 1.2)
HAND_OPENING = 0.08  # m, the Panda's maximal finger width
DEFAULT_MAX_WIDTH = 0.05  # m, a fitted object's smaller horizontal extent at size scale 1
RANDOM_URDF_MESH_SCALE = 0.015  # the scale every random_urdfs/NNN/NNN.urdf applies to its mesh
RANDOM_URDF_MASS = 0.1  # kg, the mass every random_urdfs URDF declares
BROKEN_RANDOM_URDFS = (168,)  # 168.obj has only NaN vertices: in the split, never drawn
PRIMITIVE_KINDS = ("box", "cylinder", "sphere", "capsule")
PRIMITIVE_GRID = 0.005  # m: drawn dimensions are rounded to it so built shapes can be cached
TOYS = (  # pybullet_data extras; the ones wider than the hand are fitted like any mesh
    "duck_vhacd.urdf",
    "teddy_vhacd.urdf",
    "lego/lego.urdf",
    "jenga/jenga.urdf",
    "objects/mug.urdf",
    "sphere_small.urdf",
)
SET_NAMES = ("cube", "primitives", "random_urdfs", "random_urdfs_train", "random_urdfs_test", "toys")
SPEC_KEYS = ("sets", "paths", "max_width", "scale")


@dataclass(frozen=True)
class ObjectChoice:
    """One object as drawn for an episode, before the episode's size scale.

    ``kind`` is ``urdf`` (loadURDF), ``mesh`` (an OBJ built with createCollisionShape) or a
    primitive kind; ``dims`` are a primitive's dimensions (box: x, y, z; cylinder: radius, height;
    sphere: radius; capsule: radius, length of the straight part, lying along x).
    """

    name: str
    kind: str
    path: str = ""
    scale: float = 1.0  # file units -> m, fitting included
    dims: tuple[float, ...] = ()


@dataclass(frozen=True)
class Geometry:
    """An object's bounding box in its own frame (base = centre of mass) at size scale 1."""

    extents: tuple[float, float, float]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # bounding-box centre - base position
    mass: float = 0.1  # kg, the object's own mass
    lateral_friction: float = 1.0

    @property
    def rest_height(self) -> float:
        """Height of the base above the ground when the object stands upright."""
        return self.extents[2] / 2 - self.offset[2]


def primitive_geometry(kind: str, dims: Sequence[float]) -> Geometry:
    """Primitives are built centred on their base, so only the extents vary."""
    if kind == "box":
        extents = tuple(dims)
    elif kind == "cylinder":
        extents = (2 * dims[0], 2 * dims[0], dims[1])
    elif kind == "sphere":
        extents = (2 * dims[0],) * 3
    elif kind == "capsule":
        extents = (dims[1] + 2 * dims[0], 2 * dims[0], 2 * dims[0])
    else:
        raise ValueError(f"unknown primitive kind {kind!r}; valid kinds: {', '.join(PRIMITIVE_KINDS)}")
    return Geometry(tuple(float(e) for e in extents))


def _grid(rng: np.random.Generator, low: float, high: float) -> float:
    return round(float(rng.uniform(low, high)) / PRIMITIVE_GRID) * PRIMITIVE_GRID


def draw_primitive(rng: np.random.Generator) -> ObjectChoice:
    """A random box, upright cylinder, sphere or lying capsule 2-5 cm across its narrow side."""
    kind = PRIMITIVE_KINDS[int(rng.integers(len(PRIMITIVE_KINDS)))]
    if kind == "box":
        narrow = _grid(rng, 0.02, 0.05)
        dims = (narrow, _grid(rng, narrow, 0.08), _grid(rng, 0.03, 0.12))
        if rng.random() < 0.5:  # either horizontal axis may be the narrow one
            dims = (dims[1], dims[0], dims[2])
    elif kind == "cylinder":
        dims = (_grid(rng, 0.02, 0.05) / 2, _grid(rng, 0.03, 0.12))
    elif kind == "sphere":
        dims = (_grid(rng, 0.03, 0.05) / 2,)
    else:
        dims = (_grid(rng, 0.02, 0.05) / 2, _grid(rng, 0.02, 0.08))
    return ObjectChoice(f"primitives/{kind}", kind, dims=tuple(round(d, 6) for d in dims))


# --- meshes ------------------------------------------------------------------------------------


@lru_cache(maxsize=4096)
def obj_bounds(path: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(min, max) corner of an OBJ file's vertices; cached per process (files do not change)."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"mesh file not found: {path}")
    vertices = []
    with open(path, errors="replace") as f:
        for line in f:
            if line.startswith("v "):
                try:
                    vertices.append([float(x) for x in line.split()[1:4]])
                except ValueError:
                    raise ValueError(f"unparsable vertex in mesh {path}: {line.strip()!r}") from None
    points = np.array(vertices, dtype=float).reshape(-1, 3)
    if len(points) < 4 or not np.all(np.isfinite(points)):
        raise ValueError(f"mesh {path} has no usable vertices (need at least 4 finite 'v x y z' lines)")
    _check_solid(path, points)
    return tuple(points.min(0).tolist()), tuple(points.max(0).tolist())


def _check_solid(path: str, points: np.ndarray) -> None:
    """Refuse a mesh of zero volume (its vertices on one plane, one line or one point): PyBullet
    would build a collision shape without thickness from it, no object to grasp. The smallest spread
    across the vertices' principal axes, against the largest, is zero for such a mesh whatever its
    orientation."""
    spread = np.linalg.svd(points - points.mean(0), compute_uv=False)
    if spread[-1] <= 1e-6 * max(spread[0], 1e-12):
        raise ValueError(
            f"mesh {path} has zero volume (its vertices lie on one plane or line); an object "
            "needs a solid mesh"
        )


def mesh_geometry(path: str, scale: float) -> Geometry:
    """Meshes are built with their bounding-box centre at the base, so the offset is zero."""
    low, high = obj_bounds(path)
    return Geometry(tuple((h - lo) * scale for lo, h in zip(low, high)), mass=RANDOM_URDF_MASS)


def fit_scale(extents: Sequence[float], max_width: float) -> float:
    """Shrink (never grow) an object so its smaller horizontal extent is at most ``max_width``."""
    narrow = min(extents[0], extents[1])
    return min(1.0, max_width / narrow) if narrow > 0 else 1.0


def random_urdf_dir() -> str:
    return os.path.join(pybullet_data.getDataPath(), "random_urdfs")


def random_urdf_numbers(split: str) -> list[int]:
    """The fixed split: ``test`` = numbers ending in 0 (100), ``train`` = the other 900."""
    numbers = range(1000)
    if split == "test":
        return [n for n in numbers if n % 10 == 0]
    if split == "train":
        return [n for n in numbers if n % 10 != 0]
    return list(numbers)


def random_urdf_choice(number: int, max_width: float) -> ObjectChoice:
    path = os.path.join(random_urdf_dir(), f"{number:03d}", f"{number:03d}.obj")
    native = mesh_geometry(path, RANDOM_URDF_MESH_SCALE)
    scale = RANDOM_URDF_MESH_SCALE * fit_scale(native.extents, max_width)
    return ObjectChoice(f"random_urdfs/{number:03d}", "mesh", path, round(scale, 9))


# --- the spec ----------------------------------------------------------------------------------


@dataclass
class ObjectSpec:
    """``objects=`` resolved: groups drawn equally often, each a list of lazy entries."""

    groups: list[list[Any]] = field(default_factory=list)  # entries: ObjectChoice | int | "primitive"
    group_names: list[str] = field(default_factory=list)
    max_width: float = DEFAULT_MAX_WIDTH


def _parse(spec: Any) -> tuple[list[str], list[str], float, Any]:
    if spec is None:
        spec = "cube"
    if isinstance(spec, str):
        return [spec], [], DEFAULT_MAX_WIDTH, "fit"
    if isinstance(spec, Mapping):
        unknown = set(spec) - set(SPEC_KEYS)
        if unknown:
            raise ValueError(f"unknown objects key(s) {sorted(unknown)}; valid keys: {', '.join(SPEC_KEYS)}")
        sets = spec.get("sets", [])
        sets = [sets] if isinstance(sets, str) else list(sets)
        paths = spec.get("paths", [])
        paths = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
        if not sets and not paths:
            raise ValueError("objects mapping needs 'sets' or 'paths' (or both)")
        return (
            sets,
            [str(p) for p in paths],
            float(spec.get("max_width", DEFAULT_MAX_WIDTH)),
            spec.get("scale", "fit"),
        )
    if isinstance(spec, Sequence) and spec and all(isinstance(s, str) for s in spec):
        return list(spec), [], DEFAULT_MAX_WIDTH, "fit"
    raise ValueError(
        f"objects must be a set name ({', '.join(SET_NAMES)}), a list of them, or a mapping with "
        f"keys {', '.join(SPEC_KEYS)}; got {spec!r}"
    )


def resolve(spec: Any) -> ObjectSpec:
    """Check ``objects=`` and list what each group can draw; raises at construction, not at reset."""
    sets, paths, max_width, scale = _parse(spec)
    if not (0.0 < max_width <= HAND_OPENING / SIZE_SCALES[-1]):
        raise ValueError(
            f"objects max_width must be in (0, {HAND_OPENING / SIZE_SCALES[-1]:.4f}] m so that the "
            f"largest size scale ({SIZE_SCALES[-1]}) still fits the {HAND_OPENING} m hand; got {max_width}"
        )
    out = ObjectSpec(max_width=max_width)
    for name in sets:
        out.groups.append(_set_entries(name, max_width))
        out.group_names.append(name)
    if paths:
        out.groups.append(user_entries(paths, max_width, scale))
        out.group_names.append("paths")
    return out


def _set_entries(name: str, max_width: float) -> list[Any]:
    if name == "cube":
        return [ObjectChoice("cube", "urdf", os.path.join(pybullet_data.getDataPath(), "cube_small.urdf"))]
    if name == "primitives":
        return ["primitive"]
    if name in ("random_urdfs", "random_urdfs_train", "random_urdfs_test"):
        numbers = [n for n in random_urdf_numbers(name.rpartition("_")[2]) if n not in BROKEN_RANDOM_URDFS]
        missing = [n for n in numbers if not os.path.isfile(_random_urdf_obj(n))]
        if missing:
            raise FileNotFoundError(
                f"object set {name!r}: {len(missing)} meshes missing, e.g. {_random_urdf_obj(missing[0])}"
            )
        return numbers  # scaled lazily: parsing 1000 meshes at construction would take seconds
    if name == "toys":
        return [_urdf_choice(os.path.join(pybullet_data.getDataPath(), t), max_width, "fit") for t in TOYS]
    raise ValueError(f"unknown object set {name!r}; valid sets: {', '.join(SET_NAMES)}")


def _random_urdf_obj(n: int) -> str:
    return os.path.join(random_urdf_dir(), f"{n:03d}", f"{n:03d}.obj")


def _expand(paths: Sequence[str]) -> list[str]:
    files: list[str] = []
    for pattern in paths:
        pattern = os.path.expanduser(pattern)
        if os.path.isdir(pattern):
            found = [os.path.join(pattern, f) for f in os.listdir(pattern)]
        elif any(ch in pattern for ch in "*?["):
            found = glob.glob(pattern, recursive=True)
        elif os.path.isfile(pattern):
            found = [pattern]
        else:
            raise FileNotFoundError(f"object path not found: {pattern}")
        found = sorted(f for f in found if f.lower().endswith((".urdf", ".obj")))
        if not found:
            raise FileNotFoundError(f"object path {pattern!r} matches no .urdf or .obj file")
        files.extend(found)
    return files


def user_entries(paths: Sequence[str], max_width: float, scale: Any = "fit") -> list[ObjectChoice]:
    """User files, each checked now: it parses and fits the hand at the largest size scale."""
    if not (scale == "fit" or (isinstance(scale, (int, float)) and scale > 0)):
        raise ValueError(f"objects scale must be 'fit' or a positive number, got {scale!r}")
    entries = []
    for path in _expand(paths):
        if path.lower().endswith(".obj"):
            native = mesh_geometry(path, 1.0)
            s = fit_scale(native.extents, max_width) if scale == "fit" else float(scale)
            choice = ObjectChoice(f"paths/{os.path.basename(path)}", "mesh", os.path.abspath(path), s)
            _check_fits(path, native, s)
        else:
            choice = _urdf_choice(path, max_width, scale)
        entries.append(choice)
    return entries


def _urdf_choice(path: str, max_width: float, scale: Any) -> ObjectChoice:
    native = urdf_geometry(path)
    s = fit_scale(native.extents, max_width) if scale == "fit" else float(scale)
    _check_fits(path, native, s)
    stem = os.path.splitext(os.path.basename(path))[0]
    shipped = os.path.abspath(path).startswith(pybullet_data.getDataPath())
    group = "toys" if shipped else "paths"
    return ObjectChoice(f"{group}/{stem}", "urdf", os.path.abspath(path), s)


def _check_fits(path: str, native: Geometry, scale: float) -> None:
    narrow = min(native.extents[:2]) * scale * SIZE_SCALES[-1]
    if narrow >= HAND_OPENING:
        raise ValueError(
            f"object {path} is too large for the hand: its smaller horizontal extent is "
            f"{narrow:.3f} m at size scale {SIZE_SCALES[-1]}, the hand opens {HAND_OPENING} m "
            "(use scale='fit' or a smaller scale)"
        )


@lru_cache(maxsize=256)
def urdf_geometry(path: str) -> Geometry:
    """Load a URDF once in a private client and read its bounding box, mass and friction."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"object file not found: {path}")
    client = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        try:
            body = client.loadURDF(path)
        except pybullet.error:
            raise ValueError(
                f"cannot load object URDF {path} (unparsable or a mesh it names is missing)"
            ) from None
        pos, orn = client.getBasePositionAndOrientation(body)
        if max(abs(q) for q in orn[:3]) > 1e-6:
            raise ValueError(f"object {path}: a rotated inertial frame is not supported")
        low, high = (np.array(v) for v in client.getAABB(body))
        dyn = client.getDynamicsInfo(body, -1)
        centre = (low + high) / 2 - np.array(pos)
        return Geometry(tuple((high - low).tolist()), tuple(centre.tolist()), float(dyn[0]), float(dyn[1]))
    finally:
        client.disconnect()


class ObjectSampler:
    """Draws an episode's object from a resolved spec with the env's generator.

    With a single group of a single fixed entry (the cube) it draws nothing, so the episode's other
    random values are the ones a cube-only env has always drawn.
    """

    def __init__(self, spec: Any = "cube"):
        self.spec = resolve(spec)

    def draw(self, rng: np.random.Generator) -> ObjectChoice:
        groups = self.spec.groups
        group = groups[int(rng.integers(len(groups)))] if len(groups) > 1 else groups[0]
        entry = group[int(rng.integers(len(group)))] if len(group) > 1 else group[0]
        if entry == "primitive":
            return draw_primitive(rng)
        if isinstance(entry, int):
            return random_urdf_choice(entry, self.spec.max_width)
        return entry

    def geometry(self, choice: ObjectChoice) -> Geometry:
        """The object's geometry at size scale 1 (file units and fitting applied)."""
        if choice.kind == "urdf":
            g = urdf_geometry(choice.path)
            s = choice.scale
            return Geometry(
                tuple(e * s for e in g.extents), tuple(o * s for o in g.offset), g.mass, g.lateral_friction
            )
        if choice.kind == "mesh":
            return mesh_geometry(choice.path, choice.scale)
        return primitive_geometry(choice.kind, choice.dims)


def snap_scale(scale: float) -> float:
    """The size scale nearest ``scale`` among SIZE_SCALES (shapes are cached per scale)."""
    return min(SIZE_SCALES, key=lambda s: abs(s - scale))


def tilt(quat: Sequence[float]) -> float:
    """Angle (rad) between the object's z axis and the world's: how far it has tipped over."""
    x, y, z, w = quat
    return math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (x * x + y * y))))
