"""Watch the scripted expert: a few seeded episodes rendered offscreen to a GIF and a contact sheet.

    rlgrasp-demo [--episodes 3] [--randomization default] [--objects cube] [--out outputs/demo]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert


def run(episodes: int, randomization: str, out: Path, seed: int = 0, objects: str = "cube") -> float:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    env = PandaGraspEnv(randomization=randomization, render_mode="rgb_array", objects=objects, ee_yaw=True)
    expert = ScriptedExpert(env.obs_slices, action_dim=env.action_dim)
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
        print(f"episode {episode} (seed {seed + episode}, {info['object']}): success={successes[-1]} "
              f"lift={float(info['lift_height']) * 100:.1f} cm")
    env.close()

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--randomization", default="default")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", default="cube", help="object set, e.g. primitives or random_urdfs_test")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    args = parser.parse_args()
    run(args.episodes, args.randomization, args.out, args.seed, args.objects)


if __name__ == "__main__":
    main()
