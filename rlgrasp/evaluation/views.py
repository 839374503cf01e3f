"""What a camera policy saw, as pictures beside the scene: depth colormapped, RGB as it is.

A video of a camera policy that showed only the scene would hide what the policy acted on (a
texture it never saw, a dark light, missing depth pixels); each frame shows the camera's view at the
scene frame's height, nearest-neighbour upscaled so that every sensor pixel stays visible.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

#: Depth colours, near (bright) to far (dark); a missing pixel (0 m) is black.
DEPTH_COLORMAP = "viridis_r"


def depth_image(depth: np.ndarray, near: float, far: float) -> np.ndarray:
    """``[1, H, W]`` metres -> ``[H, W, 3]`` uint8: ``near``..``far`` through the colormap, 0 black."""
    # Lazy: matplotlib's colormaps, which only rendered episodes need.
    from matplotlib import colormaps

    d = np.asarray(depth, np.float32).reshape(depth.shape[-2:])
    scaled = np.clip((d - near) / max(far - near, 1e-6), 0.0, 1.0)
    rgb = (colormaps[DEPTH_COLORMAP](scaled)[..., :3] * 255).round().astype(np.uint8)
    rgb[d <= 0] = 0
    return rgb


def upscale(image: np.ndarray, height: int) -> np.ndarray:
    """``[h, w, 3]`` -> ``[height, round(w * height / h), 3]`` by nearest neighbour (pixels stay crisp)."""
    h, w = image.shape[:2]
    width = max(1, round(w * height / h))
    rows = np.arange(height) * h // height
    cols = np.arange(width) * w // width
    return image[rows][:, cols]


def camera_view(obs: Any, near: float, far: float) -> np.ndarray | None:
    """The newest images of a camera env's observation side by side (``[h, w', 3]`` uint8: depth
    first, then RGB), or ``None`` for an observation without images."""
    if not isinstance(obs, Mapping):
        return None
    parts = []
    if "depth" in obs:
        parts.append(depth_image(np.asarray(obs["depth"])[-1:], near, far))  # stacked frames: the last
    if "rgb" in obs:
        parts.append(np.ascontiguousarray(np.asarray(obs["rgb"], np.uint8)[-3:].transpose(1, 2, 0)))
    return np.concatenate(parts, axis=1) if parts else None


def beside(scene: np.ndarray, view: np.ndarray | None, gap: int = 4) -> np.ndarray:
    """The scene frame with the camera's view at its right, upscaled to its height (white gap)."""
    if view is None:
        return scene
    view = upscale(view, scene.shape[0])
    spacer = np.full((scene.shape[0], gap, 3), 255, np.uint8)
    return np.concatenate([scene[..., :3], spacer, view], axis=1)


def render_frame(env: Any, obs: Any) -> np.ndarray:
    """``env.render()``, with the camera's view of ``obs`` beside it when the env has a camera."""
    scene = env.render()
    camera = getattr(getattr(env, "unwrapped", env), "camera", None)
    if camera is None:
        return scene
    return beside(scene, camera_view(obs, camera.spec.near, camera.spec.far))
