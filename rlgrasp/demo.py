"""Watch the scripted expert: a few seeded episodes rendered offscreen to a GIF and a contact sheet.

rlgrasp-demo [--episodes 3] [--randomization default] [--objects cube] [--out outputs/demo]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter

from rlgrasp.envs import PandaGraspEnv, Randomizer, ScriptedExpert
from rlgrasp.evaluation.source import ENV_ERRORS
from rlgrasp.overrides import OneLineParser, unwritable
from rlgrasp.utils import pyplot


def make_env(randomization: str, objects: str) -> PandaGraspEnv:
    """The demo's env; a bad preset or object set is a ``ValueError`` naming the flag."""
    try:
        Randomizer(randomization)
    except ValueError as exc:
        raise ValueError(f"--randomization {randomization}: {exc}") from None
    try:
        return PandaGraspEnv(
            randomization=randomization, render_mode="rgb_array", objects=objects, ee_yaw=True
        )
    except ENV_ERRORS as exc:
        raise ValueError(f"--objects {objects}: {exc}") from None


def run(episodes: int, randomization: str, out: Path, seed: int = 0, objects: str = "cube") -> float:
    """Play and render ``episodes`` episodes, then write ``expert.gif`` and ``expert.png`` into ``out``."""
    env = make_env(randomization, objects)
    expert = ScriptedExpert.for_env(env)
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
        print(
            f"episode {episode} (seed {seed + episode}, {info['object']}): success={successes[-1]} "
            f"lift={float(info['lift_height']) * 100:.1f} cm"
        )
    env.close()

    plt = pyplot()
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(4, 3), dpi=80)
    ax.axis("off")
    image = ax.imshow(frames[0])
    animation = FuncAnimation(fig, lambda i: image.set_data(frames[i]), frames=len(frames))
    animation.save(out / "expert.gif", writer=PillowWriter(fps=env.metadata["render_fps"]))
    sheet = np.concatenate([np.concatenate(frames[i : i + 10 : 2], axis=1) for i in (0, 10, 20)], axis=0)
    plt.imsave(out / "expert.png", sheet)
    print(f"success {sum(successes)}/{episodes}; wrote {out / 'expert.gif'} and {out / 'expert.png'}")
    return sum(successes) / episodes


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    """The arguments, each checked: a bad one ends the command with one line (exit code 2)."""
    parser = OneLineParser(prog="rlgrasp-demo", description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--randomization", default="default", help="preset: none, default or wide")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", default="cube", help="object set, e.g. primitives or random_urdfs_test")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes {args.episodes}: must be at least 1")
    if args.seed < 0:
        parser.error(f"--seed {args.seed}: must be at least 0")
    problem = unwritable(args.out, folder=True)
    if problem:
        parser.error(f"--out {args.out}: cannot write there: {problem}")
    try:
        make_env(args.randomization, args.objects).close()
    except ValueError as exc:
        parser.error(str(exc))
    return args


def main(argv: list[str] | None = None) -> None:
    """Console entry point ``rlgrasp-demo``."""
    args = parse(argv if argv is not None else sys.argv[1:])
    run(args.episodes, args.randomization, args.out, args.seed, args.objects)


if __name__ == "__main__":
    main()
