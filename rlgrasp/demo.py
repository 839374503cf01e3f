"""Watch the scripted expert: a few seeded episodes rendered offscreen to a GIF and a contact sheet.

rlgrasp-demo [--episodes 3] [--task lift|pick_place|push|stack] [--robot panda|kuka_iiwa|xarm6]
    [--randomization default] [--objects cube] [--out outputs/demo] [--size 320x240]
    [--camera DISTANCE YAW PITCH]

The expert is the task's (``rlgrasp.envs.experts``); a goal task's renders show its goal marker.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter

from rlgrasp.envs import PandaGraspEnv, Randomizer, expert_for
from rlgrasp.envs.robot import ROBOTS
from rlgrasp.envs.scene import ViewerConfig
from rlgrasp.envs.tasks import TASKS
from rlgrasp.evaluation.source import ENV_ERRORS
from rlgrasp.overrides import OneLineParser, unwritable
from rlgrasp.utils import pyplot

#: The viewer's camera (distance m, yaw and pitch degrees) unless ``--camera`` gives one: the env's
#: default viewer, framed on the workspace so that the object and the fingers read on the sheet.
CAMERA = (ViewerConfig.distance, ViewerConfig.yaw, ViewerConfig.pitch)


def make_env(
    randomization: str,
    objects: str,
    task: str = "lift",
    size: tuple[int, int] = (320, 240),
    camera: tuple[float, float, float] = CAMERA,
    robot: str = "panda",
) -> PandaGraspEnv:
    """The demo's env; a bad preset, object set or arm is a ``ValueError`` naming the flag."""
    try:
        Randomizer(randomization)
    except ValueError as exc:
        raise ValueError(f"--randomization {randomization}: {exc}") from None
    if task not in TASKS:
        raise ValueError(f"--task {task}: unknown task; tasks: {', '.join(TASKS)}")
    if robot not in ROBOTS:
        raise ValueError(f"--robot {robot}: unknown arm; arms: {', '.join(ROBOTS)}")
    distance, yaw, pitch = camera
    try:
        return PandaGraspEnv(
            randomization=randomization,
            render_mode="rgb_array",
            objects=objects,
            control={"ee_yaw": True},
            task=task,
            robot=robot,
            sim={
                "viewer": {
                    "width": size[0],
                    "height": size[1],
                    "distance": distance,
                    "yaw": yaw,
                    "pitch": pitch,
                }
            },
        )
    except ENV_ERRORS as exc:
        raise ValueError(f"--objects {objects}: {exc}") from None


def run(
    episodes: int,
    randomization: str,
    out: Path,
    seed: int = 0,
    objects: str = "cube",
    task: str = "lift",
    size: tuple[int, int] = (320, 240),
    camera: tuple[float, float, float] = CAMERA,
    name: str = "expert",
    robot: str = "panda",
) -> float:
    """Play and render ``episodes`` episodes, then write ``<name>.gif`` and ``<name>.png`` into ``out``."""
    env = make_env(randomization, objects, task, size, camera, robot)
    expert = expert_for(env)
    frames, successes = [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        expert.reset()
        frames.append(env.render())
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert(obs))
            frames.append(env.render())
            done = terminated or truncated
        successes.append(bool(info["is_success"]))
        measure = (
            f"goal distance={float(info['goal_distance']) * 100:.1f} cm"
            if "goal_distance" in info
            else f"lift={float(info['lift_height']) * 100:.1f} cm"
        )
        where = f"seed {seed + episode}, {info['object']}"
        print(f"episode {episode} ({where}): success={successes[-1]} {measure}")
    env.close()

    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(size[0] / 80, size[1] / 80), dpi=80)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.axis("off")
    image = ax.imshow(frames[0])
    animation = FuncAnimation(fig, lambda i: image.set_data(frames[i]), frames=len(frames))
    gif, png = out / f"{name}.gif", out / f"{name}.png"
    animation.save(gif, writer=PillowWriter(fps=env.metadata["render_fps"]))
    plt.close(fig)
    sheet = np.concatenate([np.concatenate(frames[i : i + 10 : 2], axis=1) for i in (0, 10, 20)], axis=0)
    plt.imsave(png, sheet)
    print(f"success {sum(successes)}/{episodes}; wrote {gif} and {png}")
    return sum(successes) / episodes


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    """The arguments, each checked: a bad one ends the command with one line (exit code 2)."""
    parser = OneLineParser(prog="rlgrasp-demo", description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--randomization", default="default", help="preset: none, default or wide")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", default="cube", help="object set, e.g. primitives or random_urdfs_test")
    parser.add_argument("--task", default="lift", help=f"the task: {', '.join(TASKS)}")
    parser.add_argument("--robot", default="panda", help=f"the arm: {', '.join(ROBOTS)}")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    parser.add_argument("--name", default="expert", help="file names in --out: <name>.gif, <name>.png")
    parser.add_argument("--size", default="320x240", help="frame WIDTHxHEIGHT in pixels")
    parser.add_argument(
        "--camera", type=float, nargs=3, default=list(CAMERA), metavar=("DISTANCE", "YAW", "PITCH")
    )
    args = parser.parse_args(argv)
    try:
        args.size = tuple(int(v) for v in args.size.lower().split("x"))
        if len(args.size) != 2 or min(args.size) < 16:
            raise ValueError
    except ValueError:
        parser.error(f"--size {args.size}: must be WIDTHxHEIGHT, each at least 16 pixels")
    args.camera = tuple(args.camera)
    if args.episodes < 1:
        parser.error(f"--episodes {args.episodes}: must be at least 1")
    if args.seed < 0:
        parser.error(f"--seed {args.seed}: must be at least 0")
    problem = unwritable(args.out, folder=True)
    if problem:
        parser.error(f"--out {args.out}: cannot write there: {problem}")
    try:
        make_env(args.randomization, args.objects, args.task, robot=args.robot).close()
    except ValueError as exc:
        parser.error(str(exc))
    return args


def main(argv: list[str] | None = None) -> None:
    """Console entry point ``rlgrasp-demo``."""
    args = parse(argv if argv is not None else sys.argv[1:])
    run(
        args.episodes,
        args.randomization,
        args.out,
        args.seed,
        args.objects,
        args.task,
        args.size,
        args.camera,
        args.name,
        args.robot,
    )


if __name__ == "__main__":
    main()
