"""Success of the scripted expert over seeded episodes, per randomization preset.

The expert is the proof that the task is solvable and the baseline a learned policy is compared
with. Seeds are 0..N-1, so the figures reproduce exactly.

    python scripts/bench_expert.py [--episodes 100] [--presets none default wide]
"""

from __future__ import annotations

import argparse

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert
from rlgrasp.stats import wilson_interval


def success_rate(preset: str, episodes: int) -> tuple[int, float]:
    env = PandaGraspEnv(randomization=preset)
    expert = ScriptedExpert(env.obs_slices)
    successes, steps_to_success = 0, []
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        first = None
        for step in range(env.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
            if info["is_success"] and first is None:
                first = step + 1
        successes += bool(info["is_success"])
        if first is not None:
            steps_to_success.append(first)
    env.close()
    mean_steps = sum(steps_to_success) / max(len(steps_to_success), 1)
    return successes, mean_steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--presets", nargs="+", default=["none", "default", "wide"])
    args = parser.parse_args()
    print(f"{'preset':<9}{'success at end':>16}{'95% Wilson':>18}{'steps to first success':>25}")
    for preset in args.presets:
        successes, mean_steps = success_rate(preset, args.episodes)
        low, high = wilson_interval(successes, args.episodes)
        print(f"{preset:<9}{successes:>9d}/{args.episodes:<6d}{f'[{low:.2f}, {high:.2f}]':>18}"
              f"{mean_steps:>25.1f}", flush=True)


if __name__ == "__main__":
    main()
