"""Render models: CPU ms per camera image of each arm as its model is (``low_poly_meshes: null``) and with
its low-poly render model, in one process, the two timed in turn round after round so that a
drifting machine affects both alike (the ratio is the figure to quote).

    python benchmarks/bench_render_model.py [--robot panda kuka_iiwa xarm6] [--images 200] [--rounds 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

from rlgrasp.envs import GraspEnv
from rlgrasp.envs.robot import ROBOTS
from rlgrasp.utils import markdown_table

CAMERAS = {
    "fixed depth": {"mount": "fixed", "modality": "depth"},
    "fixed rgb": {"mount": "fixed", "modality": "rgb"},
    "wrist depth": {"mount": "wrist", "modality": "depth"},
}


def cpu_ms_per_image(env: GraspEnv, images: int) -> float:
    """CPU time of this process per image (the renderer runs in it): on a shared machine the wall
    clock measures the neighbours too."""
    mount = env.robot.camera_mount() if env.camera.spec.mount == "wrist" else None
    env.camera.render(mount)
    start = time.process_time()
    for _ in range(images):
        env.camera.render(mount)
    return (time.process_time() - start) / images * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", nargs="+", default=["panda", "kuka_iiwa", "xarm6"], choices=list(ROBOTS))
    parser.add_argument("--images", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--size", type=int, default=64)
    args = parser.parse_args()
    rows = []
    for robot in args.robot:
        as_is = dataclasses.replace(ROBOTS[robot], low_poly_meshes=None)
        for name, cam in CAMERAS.items():
            camera = {**cam, "width": args.size, "height": args.size}
            envs = {
                "as is": GraspEnv(robot=as_is, camera=camera, sim={"visual": "none"}),
                "low poly": GraspEnv(robot=robot, camera=camera, sim={"visual": "none"}),
            }
            times = {k: [] for k in envs}
            for env in envs.values():
                env.reset(seed=0)
            for _ in range(args.rounds):
                for key, env in envs.items():
                    times[key].append(cpu_ms_per_image(env, args.images))
            for env in envs.values():
                env.close()
            full, low = (statistics.median(times[k]) for k in envs)
            rows.append([robot, name, f"{full:.2f}", f"{low:.2f}", f"{full / low:.1f}x"])
            print(*rows[-1], flush=True)
    head = ["robot", "camera", "as is (CPU ms/image)", "low poly (CPU ms/image)", "speed-up"]
    print(markdown_table(head, rows))


if __name__ == "__main__":
    main()
