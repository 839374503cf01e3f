"""Pictures for the docs: what each camera sees under each visual preset, and each arm at its grasp.

The words in docs/cameras.md ("the wrist camera sees one or two cells of the ground", "held-out
rings under a low light") are easier to trust next to the images a policy is given, so this script
renders them: one fixed seed, the scripted expert run until the object is between the open fingers
(the frame a grasping policy has to get right), and a grid whose rows are visual presets and whose
columns are the camera configs (``configs/cameras/<name>.yaml``), depth shown grey, normalized per
image (near dark, far light, black where the sensor has no reading), every image upscaled with
nearest-neighbour so that its pixels stay visible.

    python benchmarks/camera_grid.py                      # docs/img/camera_grid.png
    python benchmarks/camera_grid.py --arms               # docs/img/arms_grasp.png

``--arms`` renders the people's viewer (``render_mode="rgb_array"``) for each arm instead, at the
step the fingers have closed on the cube.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, ImageDraw, ImageFont

from rlgrasp.envs import GraspEnv, expert_for
from rlgrasp.evaluation.views import upscale

ROOT = Path(__file__).resolve().parents[1]
PRESETS = ("none", "default", "heldout", "wide")
CAMERAS = ("wrist_depth", "wrist_rgb", "fixed_depth", "fixed_rgb")
ARMS = ("panda", "kuka_iiwa", "xarm6")
MAX_STEPS = 60  # the expert reaches the cube in about 15-30 steps; a bound in case it never does
PAD, FONT_SIZE = 4, 14


def camera_config(name: str, size: int) -> dict:
    """The ``env.camera`` of ``configs/cameras/<name>.yaml`` at ``size`` x ``size`` pixels: the grid
    shows the configs users pick, not a copy of them that could drift."""
    path = ROOT / "configs" / "cameras" / f"{name}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in path.parent.glob("*.yaml") if p.stem != "none")
        raise SystemExit(f"--cameras {name}: no {path.name}; cameras: {', '.join(known)}")
    camera = dict(yaml.safe_load(path.read_text())["camera"])
    return {**camera, "width": size, "height": size}


def run_to(env: GraspEnv, seed: int, grasped: bool) -> tuple[dict | np.ndarray, int]:
    """Reset with ``seed`` and step the scripted expert until the object is between its open fingers
    (its ``close`` phase) or, with ``grasped``, until the fingers have closed on it (the phase after);
    the observation there and the steps it took. The last observation if the expert never gets there
    in ``MAX_STEPS``."""
    expert = expert_for(env)
    phase = expert.HOLD if grasped else "close"
    obs, _ = env.reset(seed=seed)
    expert.reset()
    for step in range(MAX_STEPS):
        if expert.phase == phase:
            return obs, step
        obs, _, terminated, truncated, _ = env.step(expert(obs))
        if terminated or truncated:
            break
    return obs, MAX_STEPS


def depth_picture(depth: np.ndarray) -> np.ndarray:
    """A depth image (metres, 0 = no reading) as grey uint8 RGB, normalized over its valid pixels so
    that the few centimetres between the object and the ground show; missing pixels black."""
    valid = depth > 0
    grey = np.zeros(depth.shape, np.uint8)
    if valid.any():
        low, high = float(depth[valid].min()), float(depth[valid].max())
        scaled = (depth - low) / max(high - low, 1e-6)
        grey[valid] = (60 + 195 * scaled[valid]).astype(np.uint8)
    return np.repeat(grey[..., None], 3, axis=-1)


def camera_row(preset: str, cameras: list[str], size: int, seed: int) -> list[np.ndarray]:
    """One preset's images, one per camera config. Configs that differ only in modality share one
    ``rgbd`` env, so their depth and RGB show the same moment under the same drawn visuals."""
    groups: dict[str, tuple[dict, list[str]]] = {}
    for name in cameras:
        config = camera_config(name, size)
        key = repr(sorted((k, v) for k, v in config.items() if k != "modality"))
        groups.setdefault(key, (config, []))[1].append(name)
    images = {}
    for config, names in groups.values():
        modalities = {camera_config(n, size)["modality"] for n in names}
        modality = modalities.pop() if len(modalities) == 1 else "rgbd"
        env = GraspEnv(
            camera={**config, "modality": modality}, sim={"visual": preset}, control={"ee_yaw": True}
        )
        try:
            obs, _ = run_to(env, seed, grasped=False)
        finally:
            env.close()
        for name in names:
            wanted = camera_config(name, size)["modality"]
            images[name] = (
                depth_picture(obs["depth"][-1]) if wanted == "depth" else np.moveaxis(obs["rgb"][-3:], 0, -1)
            )
    return [images[name] for name in cameras]


def arm_picture(arm: str, seed: int, size: tuple[int, int]) -> np.ndarray:
    """The people's viewer on ``arm`` at the step its fingers have closed on the cube."""
    viewer = {"width": size[0], "height": size[1]}
    env = GraspEnv(robot=arm, render_mode="rgb_array", sim={"viewer": viewer}, control={"ee_yaw": True})
    try:
        run_to(env, seed, grasped=True)
        return env.render()
    finally:
        env.close()


def label_width(labels: list[str]) -> int:
    """The row labels' column, in pixels: the widest label and a margin (0 with no labels)."""
    font = ImageFont.load_default(size=FONT_SIZE)
    return max(int(font.getlength(s)) + 2 * PAD for s in labels) if any(labels) else 0


def grid(rows: list[list[np.ndarray]], row_labels: list[str], col_labels: list[str]) -> Image.Image:
    """The images (all one size) in a labelled grid: column names on top, row names on the left,
    ``PAD`` white pixels after each image."""
    font = ImageFont.load_default(size=FONT_SIZE)
    height, width = rows[0][0].shape[:2]
    left, top = label_width(row_labels), FONT_SIZE + 2 * PAD
    size = (left + len(col_labels) * (width + PAD), top + len(rows) * (height + PAD))
    sheet = Image.new("RGB", size, "white")
    draw = ImageDraw.Draw(sheet)
    for c, label in enumerate(col_labels):
        draw.text((left + c * (width + PAD) + width / 2, PAD), label, fill="black", font=font, anchor="mt")
    for r, (label, images) in enumerate(zip(row_labels, rows)):
        y = top + r * (height + PAD)
        draw.text((PAD, y + height / 2), label, fill="black", font=font, anchor="lm")
        for c, image in enumerate(images):
            sheet.paste(Image.fromarray(image), (left + c * (width + PAD), y))
    return sheet


def parse(argv: list[str] | None) -> argparse.Namespace:
    """The flags; the defaults make the docs' two pictures, small values make the test's tiny grid."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", action="store_true", help="the arms at their grasp, not the cameras")
    parser.add_argument("--presets", nargs="+", default=list(PRESETS), help="visual presets (rows)")
    parser.add_argument("--cameras", nargs="+", default=list(CAMERAS), help="configs/cameras names (columns)")
    parser.add_argument("--robots", nargs="+", default=list(ARMS), help="with --arms: the arms (columns)")
    parser.add_argument("--size", type=int, default=64, help="camera images' width and height, pixels")
    parser.add_argument("--scale", type=int, default=3, help="nearest-neighbour upscaling of camera images")
    parser.add_argument("--viewer", default="320x240", help="with --arms: the viewer's WIDTHxHEIGHT")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="default: docs/img/camera_grid.png or arms_grasp.png")
    args = parser.parse_args(argv)
    if args.out is None:
        args.out = ROOT / "docs" / "img" / ("arms_grasp.png" if args.arms else "camera_grid.png")
    return args


def main(argv: list[str] | None = None) -> Path:
    """Render, write the PNG, and print the command that made it and where it went."""
    argv = sys.argv[1:] if argv is None else argv
    args = parse(argv)
    if args.arms:
        size = tuple(int(v) for v in args.viewer.lower().split("x"))
        row = [arm_picture(arm, args.seed, size) for arm in args.robots]
        sheet = grid([row], [""], list(args.robots))
    else:
        height = args.size * args.scale
        rows = [
            [upscale(im, height) for im in camera_row(p, args.cameras, args.size, args.seed)]
            for p in args.presets
        ]
        sheet = grid(rows, list(args.presets), [c.replace("_", " ") for c in args.cameras])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.out, optimize=True)
    print(f"python benchmarks/camera_grid.py {shlex.join(argv)}".rstrip())
    print(f"wrote {args.out} ({sheet.width}x{sheet.height})")
    return args.out


if __name__ == "__main__":
    main()
