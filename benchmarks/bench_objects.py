"""Reset cost and env steps/s per object set, and what a pool of parked bodies would cost instead.

The env builds each episode's object at reset and removes it before the next (``Scene.spawn``).
The alternative is a pool of bodies parked far away as static bodies, swapped in at reset; the
pool has to exist when the reset state is saved, so ``restoreState`` carries all of it. This
script times both in one process, one after the other:

- ``reset ms``: median over rounds of the mean ``env.reset`` time over ``--resets`` seeded resets,
  after one untimed pass over the same seeds (shape caches and the file cache warm);
- ``steps/s``: env steps per second with the scripted expert over ``--steps`` steps, resets
  included (one 50-step episode per reset);
- pool: ``restoreState`` + moving one parked body in, for pools of 5, 100 and 900 bodies.

    python benchmarks/bench_objects.py [--objects cube primitives ...] [--resets 100] [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert
from rlgrasp.envs.objects import SET_NAMES
from rlgrasp.envs.robot import Panda


def reset_ms(env: PandaGraspEnv, seeds: range) -> float:
    start = time.perf_counter()
    for seed in seeds:
        env.reset(seed=seed)
    return (time.perf_counter() - start) / len(seeds) * 1e3


def steps_per_second(env: PandaGraspEnv, steps: int) -> float:
    expert = ScriptedExpert.for_env(env)
    obs, _ = env.reset(seed=0)
    start = time.perf_counter()
    for i in range(steps):
        obs, _, terminated, truncated, _ = env.step(expert(obs))
        if terminated or truncated:
            obs, _ = env.reset(seed=i)
            expert.reset()
    return steps / (time.perf_counter() - start)


def pool_reset_ms(pool_size: int, resets: int = 200) -> float:
    """restoreState with ``pool_size`` parked cubes saved in it, then one cube moved in."""
    c = BulletClient(connection_mode=pybullet.DIRECT)
    c.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
    c.loadURDF(os.path.join(pybullet_data.getDataPath(), "plane.urdf"))
    Panda(c)
    cube = os.path.join(pybullet_data.getDataPath(), "cube_small.urdf")
    pool = [c.loadURDF(cube, [-5.0 - i % 30, 5.0 + i // 30, 0.025]) for i in range(pool_size)]
    for body in pool:
        c.changeDynamics(body, -1, mass=0.0)
    state = c.saveState()
    start = time.perf_counter()
    for i in range(resets):
        c.restoreState(state)
        body = pool[i % pool_size]
        c.changeDynamics(body, -1, mass=0.1, lateralFriction=1.0)
        c.resetBasePositionAndOrientation(body, [0.6, 0.0, 0.025], [0, 0, 0, 1])
    elapsed = (time.perf_counter() - start) / resets * 1e3
    c.disconnect()
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", nargs="+", default=list(SET_NAMES))
    parser.add_argument("--resets", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--randomization", default="default")
    args = parser.parse_args()
    print(f"load at reset (randomization={args.randomization}, ee_yaw=True)")
    print(f"{'objects':<20}{'reset ms':>10}{'steps/s':>10}")
    seeds = range(args.resets)
    for objects in args.objects:
        env = PandaGraspEnv(objects=objects, randomization=args.randomization, control={"ee_yaw": True})
        reset_ms(env, seeds)  # warm the caches
        ms = statistics.median(reset_ms(env, seeds) for _ in range(args.rounds))
        rate = steps_per_second(env, args.steps)
        print(f"{objects:<20}{ms:>10.2f}{rate:>10.0f}", flush=True)
        env.close()
    print("pool of parked cubes: restoreState + swap one in")
    for size in (5, 100, 900):
        print(
            f"{'pool of ' + str(size):<20}{np.median([pool_reset_ms(size) for _ in range(3)]):>10.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
