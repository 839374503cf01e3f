"""Collision models side by side: the scripted expert's episodes under ``mesh`` and ``primitive``.

One process, the two envs stepped in turn episode by episode (the same seeds), so that background
load hits both alike; times are the process's CPU time, which a shared machine disturbs less than
the wall clock. Per model: ms per ``env.step``, ms inside ``stepSimulation`` per step, bare stepping
of the scene after a reset (12 substeps: what ``bench_env.py`` calls bare), contact points per step
and the expert's successes.

    python benchmarks/bench_collision.py [--episodes 40] [--objects cube] [--randomization default]
"""

from __future__ import annotations

import argparse
import time

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert
from rlgrasp.envs.collision_model import COLLISION_MODELS

clock = time.process_time
BARE_STEPS = 10  # env steps' worth of bare stepping after each reset


class Run:
    """One collision model's env, its expert, and what was measured."""

    def __init__(self, model: str, objects: str, randomization: str):
        self.model = model
        self.env = PandaGraspEnv(objects=objects, randomization=randomization, sim={"collision_model": model})
        self.expert = ScriptedExpert.for_env(self.env)
        self.raw_step = self.env.client.stepSimulation
        self.env.client.stepSimulation = self._timed_step  # an instance attribute wins
        self.physics = self.step = self.bare = 0.0
        self.steps = self.contacts = self.successes = 0

    def _timed_step(self) -> None:
        start = clock()
        self.raw_step()
        self.physics += clock() - start

    def episode(self, seed: int) -> None:
        env = self.env
        env.reset(seed=seed)
        start = clock()
        for _ in range(BARE_STEPS * env.sim.substeps):
            self.raw_step()
        self.bare += clock() - start
        obs, _ = env.reset(seed=seed)
        self.expert.reset()
        for _ in range(env.sim.max_episode_steps):
            action = self.expert(obs)
            start = clock()
            obs, _, _, _, info = env.step(action)
            self.step += clock() - start
            self.steps += 1
            self.contacts += len(env.client.getContactPoints())
        self.successes += bool(info["is_success"])

    def row(self, episodes: int) -> str:
        n, bare = self.steps, self.bare / (episodes * BARE_STEPS)
        return (
            f"{self.model:<11}{self.step / n * 1e3:>9.2f}{self.physics / n * 1e3:>10.2f}"
            f"{bare * 1e3:>9.2f}{bare / (self.step / n):>10.2f}{self.contacts / n:>10.1f}"
            f"{self.successes:>7d}/{episodes}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--objects", default="cube", help="object set (rlgrasp.envs.objects)")
    parser.add_argument("--randomization", default="default")
    args = parser.parse_args()
    runs = [Run(model, args.objects, args.randomization) for model in COLLISION_MODELS]
    for seed in range(args.episodes):
        for run in runs if seed % 2 == 0 else runs[::-1]:
            run.episode(seed)
    print(
        f"objects={args.objects}  randomization={args.randomization}  episodes={args.episodes}  "
        "(CPU ms per env step)"
    )
    print(
        f"{'model':<11}{'env.step':>9}{'physics':>10}{'bare':>9}{'env/bare':>10}{'contacts':>10}{'expert':>11}"
    )
    for run in runs:
        print(run.row(args.episodes))
    mesh, other = runs[0], runs[1]
    print(
        f"{other.model}/{mesh.model}: env.step {other.step / mesh.step:.3f}, physics "
        f"{other.physics / mesh.physics:.3f}, bare {other.bare / mesh.bare:.3f}"
    )
    for run in runs:
        run.env.close()


if __name__ == "__main__":
    main()
