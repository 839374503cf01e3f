"""Cameras a robot could carry: depth in metres and RGB, from the wrist or from a fixed mount.

Rendered with PyBullet's TinyRenderer (CPU, no display), once per control step. The cost is the
robot's visual meshes and the pixels each triangle covers, so a camera renders the robot's low-poly
model (``Robot.render_model``), and a depth-only camera adds the ground itself (``ground_depth``):
the flat ground covers most pixels and cost TinyRenderer two thirds of each image. docs/cameras.md
has the figures.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

MOUNTS = ("wrist", "fixed")
MODALITIES = ("depth", "rgb", "rgbd")
MAX_SIZE = 512
MAX_FRAMES = 8
#: The observation entry of a camera's ground mask (``CameraSpec.ground_mask``).
GROUND_MASK_KEY = "ground_mask"
#: Where each mount looks from by default: for ``wrist`` in the hand's frame (its z axis points
#: along the fingers), for ``fixed`` in the world frame.
MOUNT_DEFAULTS = {
    "wrist": {"eye": (0.06, 0.0, 0.0), "target": (0.0, 0.0, 0.3), "up": (1.0, 0.0, 0.0)},
    "fixed": {"eye": (1.05, 0.0, 0.55), "target": (0.6, 0.0, 0.0), "up": (0.0, 0.0, 1.0)},
}


@dataclass(frozen=True)
class CameraSpec:
    """One camera: where it is, what it sees, what it returns. ``None`` pose entries take the mount's
    defaults (``MOUNT_DEFAULTS``)."""

    mount: str = "wrist"
    modality: str = "depth"
    width: int = 64
    height: int = 64
    fov: float = 70.0  # vertical field of view, degrees
    near: float = 0.02  # m; depth is clipped to [near, far]
    far: float = 1.0
    eye: tuple[float, float, float] | None = None
    target: tuple[float, float, float] | None = None
    up: tuple[float, float, float] | None = None
    # The last ``frames`` images, oldest first, stacked along the channels: with more than one the
    # policy sees motion (a cube starting to tip or slip), which one image cannot show.
    frames: int = 1
    # For training only: with k > 0 the env also reports where the object lies in this camera's
    # image, the share of object pixels in each cell of a k x k grid (``object_cells``), as a part
    # of the privileged state. A camera learner's auxiliary head can regress its image features
    # onto it (docs/algorithms.md); no policy reads it and no robot needs it.
    object_cells: int = 0
    # For training only: with an RGB camera the env also returns ``ground_mask``, 1 where the ground
    # shows in each image (uint8, one channel a frame), so that a learner can put other grounds
    # behind the object in its replayed images (``algo.augment.ground_swap``); no policy reads it.
    ground_mask: bool = False

    @staticmethod
    def from_config(cfg: Mapping[str, Any]) -> CameraSpec:
        """A spec from a config mapping; an unknown key or a bad value fails in one line naming it."""
        known = {f.name for f in fields(CameraSpec)}
        unknown = sorted(set(cfg) - known)
        if unknown:
            raise ValueError(f"camera: unknown key {unknown[0]!r}; valid keys: {', '.join(sorted(known))}")
        values = {
            k: tuple(float(x) for x in v) if k in ("eye", "target", "up") and v is not None else v
            for k, v in cfg.items()
        }
        spec = CameraSpec(**values)
        spec.validate()
        return spec

    def validate(self) -> None:
        if self.mount not in MOUNTS:
            raise ValueError(f"camera.mount={self.mount!r}: valid mounts: {', '.join(MOUNTS)}")
        if self.modality not in MODALITIES:
            raise ValueError(f"camera.modality={self.modality!r}: valid modalities: {', '.join(MODALITIES)}")
        for key in ("width", "height"):
            value = getattr(self, key)
            if not (isinstance(value, int) and 1 <= value <= MAX_SIZE):
                raise ValueError(f"camera.{key}={value!r}: must be an integer from 1 to {MAX_SIZE}")
        if not (isinstance(self.frames, int) and 1 <= self.frames <= MAX_FRAMES):
            raise ValueError(f"camera.frames={self.frames!r}: must be an integer from 1 to {MAX_FRAMES}")
        k = self.object_cells
        if not (isinstance(k, int) and k >= 0 and (k == 0 or (self.width % k == 0 and self.height % k == 0))):
            raise ValueError(
                f"camera.object_cells={k!r}: must be 0 (off) or a whole number of cells dividing the "
                f"image's width {self.width} and height {self.height}"
            )
        if not isinstance(self.ground_mask, bool) or (self.ground_mask and "rgb" not in self.keys):
            raise ValueError(
                f"camera.ground_mask={self.ground_mask!r}: must be true or false, and true only with RGB "
                f"(modality rgb or rgbd; here {self.modality}): a depth camera draws no ground body"
            )
        if not 0 < self.fov < 180:
            raise ValueError(f"camera.fov={self.fov!r}: must be between 0 and 180 degrees")
        if not 0 < self.near < self.far:
            raise ValueError(f"camera.near={self.near!r}, camera.far={self.far!r}: need 0 < near < far")
        for key in ("eye", "target", "up"):
            value = getattr(self, key)
            if value is not None and (len(value) != 3 or not all(map(math.isfinite, value))):
                raise ValueError(f"camera.{key}={list(value)!r}: must be three finite numbers")

    def pose(self) -> dict[str, np.ndarray]:
        defaults = MOUNT_DEFAULTS[self.mount]
        return {k: np.array(getattr(self, k) or defaults[k], dtype=float) for k in ("eye", "target", "up")}

    @property
    def keys(self) -> tuple[str, ...]:
        """The observation entries this camera fills."""
        return {"depth": ("depth",), "rgb": ("rgb",), "rgbd": ("depth", "rgb")}[self.modality]

    def spaces(self) -> dict[str, gym.spaces.Box]:
        """Channel-first image spaces: depth float32 metres in [near, far] (0: no reading, as depth
        sensors report a missing pixel), RGB uint8; ``frames`` images stacked along the channels."""
        out = {}
        if "depth" in self.keys:
            out["depth"] = gym.spaces.Box(0.0, self.far, (self.frames, self.height, self.width), np.float32)
        if "rgb" in self.keys:
            out["rgb"] = gym.spaces.Box(0, 255, (3 * self.frames, self.height, self.width), np.uint8)
        if self.ground_mask:
            out[GROUND_MASK_KEY] = gym.spaces.Box(0, 1, (self.frames, self.height, self.width), np.uint8)
        return out


class ImageHistory:
    """The last ``frames`` images of each key, stacked oldest first along the channels; an episode
    starts with its first image repeated. Hand-written: TorchRL's ``CatFrames`` stacks in the
    collector, so a gymnasium user, evaluation and export would see other shapes than training, and
    gymnasium's ``FrameStackObservation`` stacks every entry (state, privileged) on a new axis."""

    def __init__(self, frames: int):
        self.frames = frames
        self.history: dict[str, collections.deque] = {}

    def push(self, images: dict[str, np.ndarray], first: bool) -> dict[str, np.ndarray]:
        if self.frames == 1:
            return images
        out = {}
        for key, image in images.items():
            if first or key not in self.history:
                self.history[key] = collections.deque([image] * self.frames, maxlen=self.frames)
            else:
                self.history[key].append(image)
            out[key] = np.concatenate(self.history[key], axis=0)
        return out


@dataclass
class Lighting:
    """TinyRenderer's light for one episode (``getCameraImage`` keywords)."""

    direction: tuple[float, float, float] = (0.3, 0.3, 1.0)
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.6
    diffuse: float = 0.35
    specular: float = 0.05

    def keywords(self) -> dict[str, Any]:
        return {
            "lightDirection": list(self.direction),
            "lightColor": list(self.colour),
            "lightAmbientCoeff": self.ambient,
            "lightDiffuseCoeff": self.diffuse,
            "lightSpecularCoeff": self.specular,
        }


def ray_grid(spec: CameraSpec) -> np.ndarray:
    """Each pixel's ray in the camera's frame (right, up, forward), scaled to unit forward length,
    so that a hit at parameter t lies t metres deep; rows from the top, as images arrive. Each ray
    passes through its pixel's lower-left corner, where TinyRenderer samples (tests/test_cameras.py:
    the computed ground matches the rendered one to micrometres)."""
    tan_v = math.tan(math.radians(spec.fov) / 2)
    tan_h = tan_v * spec.width / spec.height
    x = (np.arange(spec.width) / spec.width * 2 - 1) * tan_h
    y = (1 - (np.arange(spec.height) + 1) / spec.height * 2) * tan_v
    grid = np.ones((spec.height, spec.width, 3), np.float32)
    grid[..., 0], grid[..., 1] = x[None, :], y[:, None]
    return grid


def ground_depth(
    rays: np.ndarray, eye: np.ndarray, target: np.ndarray, up: np.ndarray, height: float = 0.0
) -> np.ndarray:
    """Depth (m, along the view axis) of the plane z = ``height`` at each pixel; inf where a ray
    never meets it. Hand-written: TinyRenderer shades every ground pixel, which a depth image
    does not need."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    dz = rays @ np.array([right[2], true_up[2], forward[2]], np.float32)
    with np.errstate(divide="ignore"):
        t = (height - eye[2]) / dz
    return np.where(t > 0, t, np.inf).astype(np.float32)


def object_cells(mask: np.ndarray, cells: int) -> np.ndarray:
    """A boolean ``[H, W]`` mask as the share of its true pixels in each cell of a ``cells`` x
    ``cells`` grid, row by row: float32 ``[cells * cells]`` in [0, 1]."""
    height, width = mask.shape
    grid = mask.reshape(cells, height // cells, cells, width // cells)
    return grid.mean(axis=(1, 3), dtype=np.float32).reshape(-1)


class Camera:
    """Renders one ``CameraSpec`` in one client; ``render`` returns channel-first arrays by key.
    ``ground_height``: a depth-only camera whose scene shows no ground body computes the ground
    plane at this height itself (``ground_depth``); None: the ground is a body TinyRenderer draws.
    ``segmented``: ``render`` also returns ``segmentation``, each pixel's body id (-1: none), from
    which the env takes the ground's pixels (visual randomization repaints them) and the object's
    (``object_cells``); off, TinyRenderer skips the mask, which costs it time."""

    def __init__(self, spec: CameraSpec, client: BulletClient):
        self.spec, self.client = spec, client
        self.ground_height: float | None = None
        self.segmented = False
        self.base_pose = spec.pose()
        self.fov = spec.fov
        self.offset = np.zeros(3)  # per-episode pose jitter (m), in the mount's frame
        self.tilt = np.zeros(3)  # per-episode aim jitter (m at the target), in the mount's frame
        self.lighting = Lighting()
        self._rays: np.ndarray | None = None

    def jitter(self, offset: np.ndarray, tilt: np.ndarray, fov_delta: float, lighting: Lighting) -> None:
        """This episode's deviations from the nominal camera (visual randomization)."""
        self.offset, self.tilt = np.asarray(offset, float), np.asarray(tilt, float)
        self.fov = float(np.clip(self.spec.fov + fov_delta, 1.0, 179.0))
        self.lighting = lighting
        self._rays = None

    def world_pose(self, mount_pose: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, ...]:
        """Eye, target and up in the world; ``mount_pose`` is the wrist's (position, quaternion),
        None for a fixed camera."""
        eye = self.base_pose["eye"] + self.offset
        target = self.base_pose["target"] + self.tilt
        up = self.base_pose["up"]
        if mount_pose is not None:
            position, quat = mount_pose
            rotation = np.array(self.client.getMatrixFromQuaternion(quat)).reshape(3, 3)
            eye, target, up = position + rotation @ eye, position + rotation @ target, rotation @ up
        return eye, target, up

    def view_matrix(self, mount_pose: tuple[np.ndarray, np.ndarray] | None) -> list[float]:
        eye, target, up = self.world_pose(mount_pose)
        return self.client.computeViewMatrix(eye.tolist(), target.tolist(), up.tolist())

    def rays(self) -> np.ndarray:
        """The pixel rays at this episode's field of view (made once per episode)."""
        if self._rays is None:
            self._rays = ray_grid(replace(self.spec, fov=self.fov))
        return self._rays

    def check_outside(self, body: int, mount_pose: tuple[np.ndarray, np.ndarray] | None) -> None:
        """A camera inside a link sees the inside of one mesh for ever: refuse it when the env is
        built (the robot at its neutral pose). A point-sized collision query, no body is added, so
        the physics of a seed stays as it is. The probe shape stays: PyBullet's removeCollisionShape
        only prints a warning that it does not free it."""
        probe = self.client.createCollisionShape(pybullet.GEOM_SPHERE, radius=1e-3)
        eye = self.world_pose(mount_pose)[0]
        hits = self.client.getClosestPoints(
            bodyA=-1, bodyB=body, distance=0.0, collisionShapeA=probe, collisionShapePositionA=eye.tolist()
        )
        inside = [hit[4] for hit in hits if hit[8] < 0.0]
        if inside:
            link = inside[0]
            name = "base" if link < 0 else self.client.getJointInfo(body, link)[12].decode()
            frame = "the hand's frame" if mount_pose is not None else "the world frame"
            raise ValueError(
                f"camera.eye={[round(float(x), 3) for x in self.base_pose['eye']]} ({frame}): inside the "
                f"robot's link {name} at its neutral pose; move the camera outside the robot"
            )

    def render(self, mount_pose: tuple[np.ndarray, np.ndarray] | None) -> dict[str, np.ndarray]:
        s = self.spec
        eye, target, up = self.world_pose(mount_pose)
        view = self.client.computeViewMatrix(eye.tolist(), target.tolist(), up.tolist())
        projection = self.client.computeProjectionMatrixFOV(self.fov, s.width / s.height, s.near, s.far)
        _, _, rgba, depth_buffer, segmentation = self.client.getCameraImage(
            s.width,
            s.height,
            view,
            projection,
            renderer=pybullet.ER_TINY_RENDERER,
            flags=0 if self.segmented else pybullet.ER_NO_SEGMENTATION_MASK,
            **self.lighting.keywords(),
        )
        out = {}
        if self.segmented:  # without the link-index flag, each pixel holds its body's id (-1: no body)
            out["segmentation"] = np.asarray(segmentation).reshape(s.height, s.width)
        if "depth" in s.keys:
            z = np.asarray(depth_buffer, np.float32).reshape(1, s.height, s.width)
            metres = s.far * s.near / (s.far - (s.far - s.near) * z)  # OpenGL depth buffer -> distance
            if self.ground_height is not None:
                ground = ground_depth(self.rays(), eye, target, up, self.ground_height)
                metres = np.minimum(metres, ground[None])
            out["depth"] = np.clip(metres, s.near, s.far).astype(np.float32)
        if "rgb" in s.keys:
            image = np.asarray(rgba, np.uint8).reshape(s.height, s.width, 4)[:, :, :3]
            out["rgb"] = np.ascontiguousarray(image.transpose(2, 0, 1))
        return out
