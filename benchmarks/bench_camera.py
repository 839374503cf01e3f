"""Camera cost: ms per image and env frames/s for each camera configuration against no camera.

One process, random joint_delta actions, episodes reset as they end; every configuration is timed
in turn, round after round, so a drifting machine affects all of them alike (the ratio is the
figure to quote). Prints a table and each configuration's ratio to the state env.

    python benchmarks/bench_camera.py [--steps 1500] [--rounds 3] [--size 64]

``--record PAGE/ID`` writes ``--record-camera``'s ratio to the state env (default: wrist depth) into
that row of docs/benchmarks/results.json and its page's table (benchmarks/results_file.py), met when
it is >= ``--target``:

    python benchmarks/bench_camera.py --steps 1000 --rounds 3 --record cameras/camera-cost --target 0.5
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_file, also when loaded by path
import results_file

from rlgrasp.envs import GraspEnv

CONFIGS = {
    "none (state)": None,
    "wrist depth": {"mount": "wrist", "modality": "depth"},
    "wrist rgb": {"mount": "wrist", "modality": "rgb"},
    "wrist rgbd": {"mount": "wrist", "modality": "rgbd"},
    "fixed depth": {"mount": "fixed", "modality": "depth"},
    "fixed rgb": {"mount": "fixed", "modality": "rgb"},
}


def frames_per_second(env: GraspEnv, steps: int, rng: np.random.Generator) -> float:
    env.reset(seed=int(rng.integers(1 << 30)))
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, env.action_dim))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def ms_per_image(env: GraspEnv, images: int = 300) -> float:
    mount = env.robot.camera_mount() if env.camera.spec.mount == "wrist" else None
    env.camera.render(mount)
    start = time.perf_counter()
    for _ in range(images):
        env.camera.render(mount)
    return (time.perf_counter() - start) / images * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--visual", default="default", help="visual preset of the camera envs")
    results_file.add_options(parser)
    parser.add_argument(
        "--record-camera",
        default="wrist depth",
        choices=[c for c in CONFIGS if CONFIGS[c]],
        help="with --record: the camera whose ratio to the state env is written",
    )
    parser.add_argument("--target", type=float, help="with --record: the ratio to reach")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    envs = {}
    for name, cam in CONFIGS.items():
        camera = None if cam is None else {**cam, "width": args.size, "height": args.size}
        visual = "none" if cam is None else args.visual
        envs[name] = GraspEnv(camera=camera, control={"mode": "joint_delta"}, sim={"visual": visual})
    fps = {name: [] for name in envs}
    for _ in range(args.rounds):
        for name, env in envs.items():
            fps[name].append(frames_per_second(env, args.steps, rng))
    base = statistics.median(fps["none (state)"])
    print(f"{args.size}x{args.size}, visual={args.visual}, {args.rounds} rounds x {args.steps} steps, median")
    print(f"{'camera':<14} {'ms/image':>9} {'frames/s':>9} {'vs state':>9}")
    for name, env in envs.items():
        image = "-" if env.camera is None else f"{ms_per_image(env):.2f}"
        median = statistics.median(fps[name])
        print(f"{name:<14} {image:>9} {median:>9.0f} {median / base:>9.2f}")
        env.close()
    if args.record:
        rate = statistics.median(fps[args.record_camera])
        met = "see page" if args.target is None else results_file.met_of([rate / base >= args.target])
        results_file.record(
            *args.record,
            f"{rate / base:.2f} ({rate:,.0f} against {base:,.0f} frames/s)",
            met,
            load=args.record_load,
        )


if __name__ == "__main__":
    main()
