"""The PyBullet world: one private client, the ground, and the episode's object.

The object is built at each reset and removed before the next one: a parked pool of bodies would
have to exist when the reset state is saved, and restoring a state costs more the more bodies it
holds. Collision and visual shapes are cached per object and size scale, because PyBullet never
frees a removed body's shapes.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field

import numpy as np
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.objects import ObjectChoice, obj_bounds

PRIMITIVE_COLOUR = (0.85, 0.45, 0.2, 1.0)
MESH_COLOUR = (0.57, 0.85, 0.78, 1.0)
GROUND_COLOUR = (0.8, 0.8, 0.8, 1.0)
MARKER_COLOUR = (0.1, 0.8, 0.2, 0.6)
#: Where people's renders look: above the object's nominal place (0.6, 0), so that
#: at the viewer's default distance the cube and the fingers are plainly visible and a lift stays in
#: the frame (from 1.1 m at (0.45, 0, 0.2) the cube was a few pixels across).
VIEWER_TARGET = (0.6, 0.0, 0.22)
#: The compact ground's centre along x (``use_compact_ground``): fixed apart from the viewer, since
#: the ground's texture there is what RGB cameras see and trained policies read.
GROUND_CENTRE_X = 0.45


@dataclass
class ViewerConfig:
    """``env.sim.viewer``: the camera people's renders (``render_mode``) look through, not a policy's."""

    width: int = 320
    height: int = 240
    distance: float = 0.55
    yaw: float = 40.0
    pitch: float = -20.0


@dataclass
class SimConfig:
    """``env.sim``: how the world is simulated and shown: physics stepping, episode length, the
    hand's contact shapes, the visual preset and the viewer."""

    time_step: float = 1.0 / 240.0  # one control step = substeps x time_step seconds
    substeps: int = 12
    solver_iterations: int = 20
    max_episode_steps: int = 50
    # mesh: the arm's own collision meshes; primitive: boxes and capsules for the Panda's hand and
    # fingers (rlgrasp/envs/collision_model.py). The shipped policies were trained on the meshes.
    collision_model: str = "mesh"
    visual: str = (
        "none"  # the looks drawn per episode: none | default | wide | heldout | ... (`visual` group)
    )
    viewer: ViewerConfig = field(default_factory=ViewerConfig)

    def __post_init__(self) -> None:
        """Bad values fail here, naming the key, before a physics client exists."""
        for name in ("max_episode_steps", "substeps", "solver_iterations"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"sim.{name} must be a positive integer, got {value!r}")
        if not (self.time_step > 0 and math.isfinite(self.time_step)):
            raise ValueError(f"sim.time_step must be a positive number, got {self.time_step!r}")


def data_path(name: str) -> str:
    """Absolute path of a model shipped with pybullet_data; FileNotFoundError if it is missing."""
    path = name if os.path.isabs(name) else os.path.join(pybullet_data.getDataPath(), name)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"model file not found: {path}")
    return path


class CachedClient(BulletClient):
    """A ``BulletClient`` that builds each pybullet function's client-bound partial once.

    ``BulletClient.__getattr__`` runs ``inspect.isbuiltin`` and makes a new ``functools.partial`` on
    every call; an env step makes a dozen calls, and that was a tenth of its Python time. Keeping the
    partial as an instance attribute makes later look-ups ordinary attribute reads. Disconnecting
    drops them, so that a call after ``close`` fails as before instead of reaching whichever client
    later gets the same id.
    """

    def __getattr__(self, name: str):
        attribute = super().__getattr__(name)
        if name == "disconnect":
            for key in [k for k, v in self.__dict__.items() if isinstance(v, functools.partial)]:
                del self.__dict__[key]
        elif isinstance(attribute, functools.partial):
            self.__dict__[name] = attribute
        return attribute


class Scene:
    """Owns the physics client. Connect inside the process that steps it (never before a fork)."""

    def __init__(self, time_step: float = 1.0 / 240.0, gui: bool = False, solver_iterations: int = 20):
        self.client = CachedClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        c = self.client
        c.setTimeStep(time_step)
        # Deterministic overlapping pairs make a replay after restoreState bit-identical; without
        # them the contact order, and so the result, can differ between two runs of one episode.
        # 20 solver iterations instead of PyBullet's 50: faster physics, and the scripted grasp
        # succeeds as often (docs/history/throughput.md#env-speed).
        c.setPhysicsEngineParameter(
            deterministicOverlappingPairs=1, numSolverIterations=int(solver_iterations)
        )
        self.time_step = time_step
        self.plane = c.loadURDF(data_path("plane.urdf"))
        self.ground: int | None = self.plane  # the body cameras see as the ground (None: none)
        self.object: int | None = None
        self.extras: list[int] = []  # a task's further bodies this episode (stack's base cube)
        #: The goal marker people see in renders and GIFs (``show_marker``); None: not shown.
        self.marker: int | None = None
        self.markers_visible = False
        self._shapes: dict[tuple, tuple[int, int]] = {}
        self._saved: int | None = None

    def use_compact_ground(self, half_size: float = 1.0) -> None:
        """Show the ground to cameras as a 2 m square instead of the URDF's 200 m plane, which the CPU
        renderer rasterizes slowly (its collision box, and so the physics, stay)."""
        self.client.changeVisualShape(self.plane, -1, rgbaColor=[1.0, 1.0, 1.0, 0.0])
        visual = self.client.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=[half_size, half_size, 0.0005], rgbaColor=GROUND_COLOUR
        )
        self.ground = self.client.createMultiBody(0.0, -1, visual, [GROUND_CENTRE_X, 0.0, -0.0005])

    def hide_ground(self) -> None:
        """Show no ground body to cameras: a depth-only camera computes the ground plane itself
        (``rlgrasp.envs.cameras.ground_depth``). The collision plane, and so the physics, stay."""
        self.client.changeVisualShape(self.plane, -1, rgbaColor=[1.0, 1.0, 1.0, 0.0])
        self.ground = None

    def save(self) -> None:
        """Remember the world as it is now (robot loaded, no object): each reset restores it."""
        self._saved = self.client.saveState()

    def restore(self, gravity_z: float) -> None:
        """Back to the saved world, with this episode's gravity. Restoring is bit-reproducible where
        resetting joint states alone is not (gymnasium's determinism check fails on that)."""
        self.remove_object()  # the saved state holds no object: restoring needs the same bodies
        for body in [*self.extras, *([self.marker] if self.marker is not None else [])]:
            self.client.removeBody(body)
        self.extras, self.marker = [], None
        self.client.restoreState(self._saved)
        self.client.setGravity(0, 0, gravity_z)

    def remove_object(self) -> None:
        """Remove the episode's object; call before restoring a state saved without it."""
        if self.object is not None:
            self.client.removeBody(self.object)
            self.object = None

    def spawn(self, choice: ObjectChoice, size_scale: float, position, orientation) -> int:
        """Build ``choice`` at ``size_scale`` x its own scale, at rest at the given pose."""
        self.remove_object()
        scale = choice.scale * size_scale
        if choice.kind == "urdf":
            body = self.client.loadURDF(choice.path, position, orientation, globalScaling=scale)
        else:
            collision, visual = self._shape(choice, scale)
            body = self.client.createMultiBody(0.1, collision, visual, position, orientation)
        self.object = body
        return body

    def spawn_extra(self, choice: ObjectChoice, size_scale: float, position, orientation, colour=None) -> int:
        """A further body for this episode (removed at the next restore), e.g. stack's base cube."""
        collision, visual = self._shape(choice, choice.scale * size_scale)
        body = self.client.createMultiBody(0.1, collision, visual, position, orientation)
        if colour is not None:
            self.client.changeVisualShape(body, -1, rgbaColor=list(colour))
        self.extras.append(body)
        return body

    def show_marker(self, position) -> None:
        """A green, collision-free sphere at a goal, for people's renders only (``markers_visible``:
        set by the env when it renders for people); policy cameras hide it (``hide_marker``)."""
        if not self.markers_visible:
            return
        if "marker" not in self._shapes:
            visual = self.client.createVisualShape(pybullet.GEOM_SPHERE, radius=0.02, rgbaColor=MARKER_COLOUR)
            self._shapes["marker"] = (-1, visual)
        self.marker = self.client.createMultiBody(0.0, -1, self._shapes["marker"][1], list(position))

    def set_marker_alpha(self, alpha: float) -> None:
        """Hide (0) or show (1) the goal marker: a policy's camera never sees it."""
        if self.marker is not None:
            self.client.changeVisualShape(self.marker, -1, rgbaColor=[*MARKER_COLOUR[:3], alpha])

    def _shape(self, choice: ObjectChoice, scale: float) -> tuple[int, int]:
        key = (choice.kind, choice.path, choice.dims, round(scale, 9))
        if key not in self._shapes:
            self._shapes[key] = self._build_shape(choice, scale)
        return self._shapes[key]

    def _build_shape(self, choice: ObjectChoice, scale: float) -> tuple[int, int]:
        c = self.client
        if choice.kind == "mesh":
            low, high = obj_bounds(choice.path)
            centre = [-(lo + h) / 2 * scale for lo, h in zip(low, high)]  # bounding-box centre at the base
            mesh = dict(fileName=choice.path, meshScale=[scale] * 3)
            collision = c.createCollisionShape(pybullet.GEOM_MESH, collisionFramePosition=centre, **mesh)
            visual = c.createVisualShape(
                pybullet.GEOM_MESH, visualFramePosition=centre, rgbaColor=MESH_COLOUR, **mesh
            )
            return collision, visual
        d = [x * scale for x in choice.dims]
        lying = c.getQuaternionFromEuler((0.0, 1.5707963267948966, 0.0))  # capsule axis along x
        if choice.kind == "box":
            args = dict(shapeType=pybullet.GEOM_BOX, halfExtents=[x / 2 for x in d])
            return c.createCollisionShape(**args), c.createVisualShape(**args, rgbaColor=PRIMITIVE_COLOUR)
        if choice.kind == "sphere":
            args = dict(shapeType=pybullet.GEOM_SPHERE, radius=d[0])
            return c.createCollisionShape(**args), c.createVisualShape(**args, rgbaColor=PRIMITIVE_COLOUR)
        shape = pybullet.GEOM_CYLINDER if choice.kind == "cylinder" else pybullet.GEOM_CAPSULE
        frame = [0, 0, 0, 1] if choice.kind == "cylinder" else lying
        collision = c.createCollisionShape(shape, radius=d[0], height=d[1], collisionFrameOrientation=frame)
        visual = c.createVisualShape(
            shape, radius=d[0], length=d[1], visualFrameOrientation=frame, rgbaColor=PRIMITIVE_COLOUR
        )
        return collision, visual

    def viewer_image(self, width: int, height: int, distance: float, yaw: float, pitch: float) -> np.ndarray:
        """An RGB picture of the scene for people (videos, the GUI), from an orbiting camera."""
        view = self.client.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=[VIEWER_TARGET[0], VIEWER_TARGET[1], VIEWER_TARGET[2]],
            distance=distance,
            yaw=yaw,
            pitch=pitch,
            roll=0.0,
            upAxisIndex=2,
        )
        projection = self.client.computeProjectionMatrixFOV(60.0, width / height, 0.05, 5.0)
        image = self.client.getCameraImage(
            width, height, view, projection, renderer=pybullet.ER_TINY_RENDERER
        )[2]
        return np.asarray(image, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def close(self) -> None:
        try:
            self.client.disconnect()
        except pybullet.error:
            pass
