"""Visual domain randomization: what a camera sees changes per episode, the physics does not.

Per episode (seeded, recorded in ``info["randomization"]`` as ``visual_*`` values): the object's,
the ground's and the robot's colours and procedural textures, the light, the camera's pose and
field of view, and the sensor noise of depth and RGB images. Textures are made in code (no
downloads) into a small pool per process, because PyBullet never frees a loaded texture.

Presets: ``none`` (today's look, no noise), ``default``, ``wide``, and ``heldout``, whose texture
generator, colour range and lighting range are never used by the others: evaluating on it measures
transfer to visuals a policy never saw, as ``random_urdfs_test`` does for objects.
"""

from __future__ import annotations

import colorsys
import math
import os
import struct
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs.cameras import Camera, Lighting
from rlgrasp.envs.randomization import Range
from rlgrasp.envs.robot import Robot

TEXTURE_SIZE = 64
TEXTURES_PER_KIND = 4


# --- procedural textures ------------------------------------------------------------------------
def _palette(rng: np.random.Generator, hues: Range) -> np.ndarray:
    """Two colours (0-1 RGB) whose hues lie in ``hues``."""
    hsv = [(hues.sample(rng) % 1.0, rng.uniform(0.3, 0.9), rng.uniform(0.35, 1.0)) for _ in range(2)]
    return np.array([colorsys.hsv_to_rgb(*c) for c in hsv])


def _blend(mask: np.ndarray, colours: np.ndarray) -> np.ndarray:
    return colours[0] * (1 - mask[..., None]) + colours[1] * mask[..., None]


def _noise(rng, n):
    coarse = rng.uniform(0, 1, (n // 8, n // 8))
    return np.kron(coarse, np.ones((8, 8)))


def _checker(rng, n):
    period = int(rng.choice([4, 8, 16]))
    i, j = np.indices((n, n)) // period
    return ((i + j) % 2).astype(float)


def _stripes(rng, n):
    angle, period = rng.uniform(0, math.pi), rng.uniform(4, 16)
    i, j = np.indices((n, n))
    return (np.sin((i * math.cos(angle) + j * math.sin(angle)) * 2 * math.pi / period) > 0).astype(float)


def _gradient(rng, n):
    angle = rng.uniform(0, 2 * math.pi)
    i, j = np.indices((n, n)) / n
    ramp = i * math.cos(angle) + j * math.sin(angle)
    return (ramp - ramp.min()) / max(np.ptp(ramp), 1e-9)


def _dots(rng, n):
    """A grid of discs, each nudged off its cell's centre."""
    period = int(rng.choice([8, 16]))
    i, j = np.indices((n, n))
    di = (i % period) - period / 2 + rng.uniform(-1, 1)
    dj = (j % period) - period / 2 + rng.uniform(-1, 1)
    return (np.hypot(di, dj) < period * rng.uniform(0.2, 0.4)).astype(float)


def _waves(rng, n):
    """Two or three crossing sine waves, thresholded: curved bands and islands."""
    i, j = np.indices((n, n))
    field = sum(
        np.sin((i * math.cos(a) + j * math.sin(a)) * 2 * math.pi / rng.uniform(8, 32) + rng.uniform(0, 6.3))
        for a in rng.uniform(0, math.pi, int(rng.integers(2, 4)))
    )
    return (field > 0).astype(float)


def _cells(rng, n):
    """A patchwork: each pixel takes a shade from its nearest of a dozen random points."""
    points = rng.uniform(0, n, (12, 2))
    i, j = np.indices((n, n))
    nearest = np.argmin(np.hypot(i[..., None] - points[:, 0], j[..., None] - points[:, 1]), axis=-1)
    return rng.uniform(0, 1, 12)[nearest]


def _blobs(rng, n):
    """Smooth noise (coarse cells bilinearly interpolated), thresholded at its median."""
    coarse = rng.uniform(0, 1, (5, 5))
    x = np.linspace(0, 4, n)
    rows = np.array([np.interp(x, np.arange(5), r) for r in coarse])  # 5 x n
    field = np.array([np.interp(x, np.arange(5), c) for c in rows.T]).T  # n x n
    return (field > np.median(field)).astype(float)


def _rings(rng, n):
    """Held out: concentric rings around a random centre."""
    ci, cj, period = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(5, 12)
    i, j = np.indices((n, n))
    return (np.sin(np.hypot(i - ci, j - cj) * 2 * math.pi / period) > 0).astype(float)


GENERATORS: dict[str, Callable[[np.random.Generator, int], np.ndarray]] = {
    "noise": _noise,
    "checker": _checker,
    "stripes": _stripes,
    "gradient": _gradient,
    "dots": _dots,
    "waves": _waves,
    "cells": _cells,
    "blobs": _blobs,
    "rings": _rings,
}


def write_tga(path: str, rgb: np.ndarray) -> None:
    """An uncompressed 24-bit TGA (PyBullet's loader reads it; no image library needed)."""
    height, width, _ = rgb.shape
    header = struct.pack("<BBBHHBHHHHBB", 0, 0, 2, 0, 0, 0, 0, 0, width, height, 24, 0x20)
    with open(path, "wb") as f:
        f.write(header + np.ascontiguousarray(rgb[:, :, ::-1]).tobytes())


def repaint_patterns(
    shape: tuple[int, int], hues: Range, count: int = 64, seed: int = 0, scales: tuple[int, ...] = (1,)
) -> np.ndarray:
    """``count`` channel-first uint8 images of ``shape``, each from a training generator (never the
    held-out rings) in two colours from ``hues``, drawn at the image's own scale or magnified
    ``scales[i % len(scales)]`` times (a corner of it blown up: fewer, larger cells and edges)."""
    rng = np.random.default_rng(seed)
    size = -(-max(shape) // 8) * 8  # the noise generator draws 8-pixel cells
    out = np.empty((count, 3, *shape), np.uint8)
    for i in range(count):
        image = _blend(GENERATORS[TRAIN_TEXTURES[i % len(TRAIN_TEXTURES)]](rng, size), _palette(rng, hues))
        scale = scales[i % len(scales)]
        image = image[: -(-size // scale), : -(-size // scale)].repeat(scale, 0).repeat(scale, 1)
        out[i] = (image[: shape[0], : shape[1]] * 255).astype(np.uint8).transpose(2, 0, 1)
    return out


# --- presets ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VisualPreset:
    """Ranges of one preset. ``textures``: the generators drawn from (empty: plain colours only)."""

    textures: tuple[str, ...] = ()
    texture_prob: float = 0.0  # else a plain colour
    hues: Range = Range(0.0, 0.0)
    light_azimuth: Range = Range(0.785, 0.785)  # rad
    light_elevation: Range = Range(1.13, 1.13)  # rad above the horizon
    light_ambient: Range = Range(0.6, 0.6)
    light_diffuse: Range = Range(0.35, 0.35)
    light_specular: Range = Range(0.05, 0.05)
    light_warmth: Range = Range(0.0, 0.0)  # -1 blue .. +1 orange tint of the light
    robot_grey: Range = Range(0.6, 0.6)
    camera_shift: float = 0.0  # m, each axis
    camera_tilt: float = 0.0  # m at the target, each axis (about tilt / 0.3 rad for the wrist camera)
    fov_jitter: float = 0.0  # degrees
    depth_noise: Range = Range(0.0, 0.0)  # sigma = k * depth^2 (m)
    depth_dropout: Range = Range(0.0, 0.0)  # probability of a missing (0) pixel at a depth edge
    depth_quantum: Range = Range(0.0, 0.0)  # m; 0 = none
    rgb_noise: Range = Range(0.0, 0.0)  # std, in 0-255 units
    # Per RGB frame, the probability that the ground's pixels are replaced by a pattern drawn in the
    # image itself (``VisualRandomizer.repaint_ground``): a training aid, not a look of the world.
    ground_repaint: float = 0.0
    # How many times the repaint patterns are magnified, each a share of the bank: a wrist camera sees
    # a ground texture's cells anywhere from a few pixels to half the image across.
    repaint_scales: tuple[int, ...] = (1,)
    recolour: bool = False  # false: the scene keeps its own colours (preset none)


DEFAULT_TEXTURES = ("noise", "checker", "stripes", "gradient")
# `wide` draws from twice the generators, curved and polygonal edges among them, so that the held-out
# rings are not the only curved edge a student meets (in 15 minutes of RGB distillation it did not
# yet help: docs/benchmarks/cameras.md).
TRAIN_TEXTURES = DEFAULT_TEXTURES + ("dots", "waves", "cells", "blobs")
_DEFAULT = VisualPreset(
    textures=DEFAULT_TEXTURES,
    texture_prob=0.7,
    hues=Range(0.0, 0.7),
    light_azimuth=Range(-math.pi, math.pi),
    light_elevation=Range(0.7, 1.45),
    light_ambient=Range(0.45, 0.75),
    light_diffuse=Range(0.2, 0.5),
    light_specular=Range(0.0, 0.1),
    light_warmth=Range(-0.3, 0.3),
    robot_grey=Range(0.3, 0.9),
    camera_shift=0.01,
    camera_tilt=0.01,
    fov_jitter=2.0,
    depth_noise=Range(0.0, 0.004),
    depth_dropout=Range(0.0, 0.2),
    depth_quantum=Range(0.0, 0.002),
    rgb_noise=Range(0.0, 4.0),
    recolour=True,
)
VISUAL_PRESETS: dict[str, VisualPreset] = {
    "none": VisualPreset(),
    "default": _DEFAULT,
    "wide": VisualPreset(
        textures=TRAIN_TEXTURES,
        texture_prob=0.8,
        hues=Range(0.0, 0.7),
        light_azimuth=Range(-math.pi, math.pi),
        light_elevation=Range(0.6, 1.5),
        light_ambient=Range(0.4, 0.8),
        light_diffuse=Range(0.15, 0.6),
        light_specular=Range(0.0, 0.15),
        light_warmth=Range(-0.5, 0.5),
        robot_grey=Range(0.2, 1.0),
        camera_shift=0.02,
        camera_tilt=0.02,
        fov_jitter=4.0,
        depth_noise=Range(0.0, 0.008),
        depth_dropout=Range(0.0, 0.35),
        depth_quantum=Range(0.0, 0.004),
        rgb_noise=Range(0.0, 8.0),
        recolour=True,
    ),
    # `default`, with half the RGB frames' ground replaced by a random pattern at the image's own
    # scale, a new one each frame: a wrist camera sees one or two cells of a ground texture, so
    # `default` shows the student few ground edges, and the held-out rings' curved edge misled it.
    # Repainted grounds put every training generator's edges (curved ones too; never rings) behind
    # the object, so that the ground's look carries nothing the student could key on (measured on
    # the RGB objects student: no gain in success, docs/benchmarks/cameras.md).
    "repaint": replace(_DEFAULT, ground_repaint=0.5),
    # `repaint` with the patterns also magnified 2 and 4 times: the checker ground the training
    # visuals draw fills a wrist image with one or two cells and a straight edge, which the
    # image-scale patterns never show.
    "repaint_scales": replace(_DEFAULT, ground_repaint=0.5, repaint_scales=(1, 2, 4)),
    # Never seen in training: the rings generator, hues 0.75-0.95 (violet to pink) and a low light;
    # everything else as `default`.
    "heldout": replace(
        _DEFAULT, textures=("rings",), hues=Range(0.75, 0.95), light_elevation=Range(0.3, 0.55)
    ),
}


def visual_preset(spec: str | Mapping[str, Any] | None) -> VisualPreset:
    if spec is None:
        return VISUAL_PRESETS["none"]
    if isinstance(spec, str):
        if spec not in VISUAL_PRESETS:
            raise ValueError(f"unknown visual preset {spec!r}; valid presets: {', '.join(VISUAL_PRESETS)}")
        return VISUAL_PRESETS[spec]
    raise ValueError(f"visual must be a preset name ({', '.join(VISUAL_PRESETS)}), got {spec!r}")


class TexturePool:
    """``TEXTURES_PER_KIND`` textures of each generator, made once per process and client."""

    def __init__(self, client: BulletClient, kinds: tuple[str, ...], hues: Range, seed: int = 0):
        self.ids: dict[str, list[int]] = {}
        folder = tempfile.mkdtemp(prefix="rlgrasp-textures-")
        rng = np.random.default_rng(seed)
        for kind in kinds:
            self.ids[kind] = []
            for i in range(TEXTURES_PER_KIND):
                image = _blend(GENERATORS[kind](rng, TEXTURE_SIZE), _palette(rng, hues))
                path = os.path.join(folder, f"{kind}_{i}.tga")
                write_tga(path, (image * 255).astype(np.uint8))
                self.ids[kind].append(client.loadTexture(path))
                os.remove(path)  # loaded: PyBullet keeps its own copy
        os.rmdir(folder)


class VisualRandomizer:
    """Draws and applies one episode's visuals; corrupts each image as a real sensor would."""

    def __init__(self, spec: str | Mapping[str, Any] | None, client: BulletClient):
        self.preset = visual_preset(spec)
        self.client = client
        p = self.preset
        self.pool = TexturePool(client, p.textures, p.hues) if p.textures else None
        self._patterns: np.ndarray | None = None  # the repaint patterns, made at the first image

    def repaint_ground(
        self, images: dict[str, np.ndarray], mask: np.ndarray, rng: np.random.Generator
    ) -> None:
        """With the preset's probability, the RGB image's ground pixels (``mask``) take a pattern from
        a bank, rolled and flipped at random: a fresh background each frame at the cost of a copy."""
        if "rgb" not in images or rng.uniform() >= self.preset.ground_repaint:
            return
        rgb = images["rgb"]
        if self._patterns is None or self._patterns.shape[-2:] != rgb.shape[-2:]:
            scales = self.preset.repaint_scales
            self._patterns = repaint_patterns(rgb.shape[-2:], self.preset.hues, scales=scales)
        pattern = self._patterns[rng.integers(len(self._patterns))]
        pattern = np.roll(pattern, tuple(rng.integers(0, rgb.shape[-2:])), axis=(1, 2))
        if rng.uniform() < 0.5:
            pattern = pattern[:, ::-1]
        images["rgb"] = np.where(mask, pattern, rgb)

    def sample(self, rng: np.random.Generator) -> dict[str, float]:
        """This episode's values (empty for ``none``), in a fixed order: same seed, same draws."""
        p = self.preset
        if not p.recolour:
            return {}
        v: dict[str, float] = {}
        for surface in ("object", "ground"):
            textured = bool(rng.uniform() < p.texture_prob)
            v[f"visual_{surface}_texture"] = float(rng.integers(len(p.textures))) if textured else -1.0
            v[f"visual_{surface}_texture_index"] = float(rng.integers(TEXTURES_PER_KIND))
            v[f"visual_{surface}_hue"] = p.hues.sample(rng) % 1.0
            v[f"visual_{surface}_value"] = float(rng.uniform(0.4, 1.0))
        v["visual_robot_grey"] = p.robot_grey.sample(rng)
        for name in ("azimuth", "elevation", "ambient", "diffuse", "specular", "warmth"):
            v[f"visual_light_{name}"] = getattr(p, f"light_{name}").sample(rng)
        for axis in "xyz":
            v[f"visual_camera_shift_{axis}"] = float(rng.uniform(-p.camera_shift, p.camera_shift))
        for axis in "xyz":
            v[f"visual_camera_tilt_{axis}"] = float(rng.uniform(-p.camera_tilt, p.camera_tilt))
        v["visual_fov_delta"] = float(rng.uniform(-p.fov_jitter, p.fov_jitter))
        for name in ("depth_noise", "depth_dropout", "depth_quantum", "rgb_noise"):
            v[f"visual_{name}"] = getattr(p, name).sample(rng)
        return v

    def apply(
        self, v: Mapping[str, float], bodies: dict[str, int], robot: Robot, camera: Camera | None
    ) -> None:
        """Recolour the object and the ground, grey the robot, move the camera and set the light."""
        if not v:
            return
        for surface in ("object", "ground"):
            if bodies[surface] is not None:  # a depth-only camera's ground is no body
                self._paint(bodies[surface], v, surface)
        grey = v["visual_robot_grey"]
        for link in robot.visible_links:
            self.client.changeVisualShape(robot.body, link, rgbaColor=[grey, grey, grey, 1.0])
        if camera is not None:
            camera.jitter(
                [v[f"visual_camera_shift_{a}"] for a in "xyz"],
                [v[f"visual_camera_tilt_{a}"] for a in "xyz"],
                v["visual_fov_delta"],
                _lighting(v),
            )

    def _paint(self, body: int, v: Mapping[str, float], surface: str) -> None:
        kind = int(v[f"visual_{surface}_texture"])
        if kind >= 0:
            texture = self.pool.ids[self.preset.textures[kind]][int(v[f"visual_{surface}_texture_index"])]
            self.client.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1])
            return
        colour = colorsys.hsv_to_rgb(v[f"visual_{surface}_hue"], 0.7, v[f"visual_{surface}_value"])
        self.client.changeVisualShape(body, -1, textureUniqueId=-1, rgbaColor=[*colour, 1.0])

    @staticmethod
    def corrupt(images: dict[str, np.ndarray], v: Mapping[str, float], rng: np.random.Generator) -> None:
        """Depth: error growing with distance, quantization, missing pixels at edges; RGB: noise."""
        if not v:
            return
        if "depth" in images:
            d = images["depth"]
            if v["visual_depth_noise"] > 0:
                noise = rng.standard_normal(d.shape, dtype=np.float32)
                noise *= d
                noise *= d
                d += noise * np.float32(v["visual_depth_noise"])
            if v["visual_depth_quantum"] > 0:
                quantum = np.float32(v["visual_depth_quantum"])
                np.round(d / quantum, out=d)
                d *= quantum
            if v["visual_depth_dropout"] > 0:
                edges = np.zeros(d.shape, bool)
                edges[..., 1:, :] |= np.abs(np.diff(d, axis=-2)) > 0.02
                edges[..., :, 1:] |= np.abs(np.diff(d, axis=-1)) > 0.02
                at_edges = np.flatnonzero(edges)  # draws for edge pixels only: a few hundred, not 4,096
                d.reshape(-1)[at_edges[rng.random(at_edges.size) < v["visual_depth_dropout"]]] = 0.0
            np.clip(d, 0.0, None, out=d)
        if "rgb" in images and v["visual_rgb_noise"] > 0:
            noisy = images["rgb"] + rng.standard_normal(images["rgb"].shape) * v["visual_rgb_noise"]
            images["rgb"] = np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def _lighting(v: Mapping[str, float]) -> Lighting:
    az, el = v["visual_light_azimuth"], v["visual_light_elevation"]
    warmth = v["visual_light_warmth"]
    return Lighting(
        direction=(math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)),
        colour=(1.0 - 0.3 * max(-warmth, 0.0), 1.0 - 0.15 * abs(warmth), 1.0 - 0.3 * max(warmth, 0.0)),
        ambient=v["visual_light_ambient"],
        diffuse=v["visual_light_diffuse"],
        specular=v["visual_light_specular"],
    )
