"""Env steps/s of PandaGraspEnv per control mode against bare PyBullet stepping of the same scene.

Measured in one process, interleaved in rounds so that background load hits both alike; each figure
is the median over rounds. Bare stepping = the same scene after a reset (arm holding its pose under
position control, object at rest), ``substeps`` calls to ``stepSimulation`` per env step. Because a
moving arm makes contacts that an idle one does not, the table also gives the share of env time
spent inside ``stepSimulation`` during the env run: 1 - that share is the env's own overhead.

    python benchmarks/bench_env.py [--steps 1000] [--rounds 5] [--randomization default] [--objects cube]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from rlgrasp.envs import CONTROL_MODES, PandaGraspEnv, ScriptedExpert


class PhysicsTimer:
    """Wraps a client's stepSimulation to add up the time spent in it."""

    def __init__(self, env: PandaGraspEnv):
        self.seconds = 0.0
        self._step = env.client.stepSimulation
        env.client.stepSimulation = self  # an instance attribute wins over BulletClient.__getattr__

    def __call__(self):
        start = time.perf_counter()
        self._step()
        self.seconds += time.perf_counter() - start


def env_rate(env: PandaGraspEnv, steps: int, policy) -> tuple[float, float]:
    """(steps/s, share of the time inside stepSimulation)."""
    timer = env.client.stepSimulation
    timer.seconds = 0.0
    obs, _ = env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(policy(obs))
        if terminated or truncated:
            obs, _ = env.reset()
            getattr(policy, "reset", lambda: None)()
    elapsed = time.perf_counter() - start
    return steps / elapsed, timer.seconds / elapsed


def bare_rate(env: PandaGraspEnv, steps: int) -> float:
    env.reset(seed=0)
    step = env.client.stepSimulation._step
    start = time.perf_counter()
    for _ in range(steps * env.substeps):
        step()
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--randomization", default="default")
    parser.add_argument("--objects", default="cube", help="object set (rlgrasp.envs.objects)")
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    print(f"randomization={args.randomization}  objects={args.objects}  steps/round={args.steps}  "
          f"rounds={args.rounds}")
    print(f"{'control_mode':<14}{'policy':<9}{'env steps/s':>12}{'bare steps/s':>13}{'ratio':>7}"
          f"{'physics share':>15}")
    bare_env = PandaGraspEnv(randomization=args.randomization, objects=args.objects)
    PhysicsTimer(bare_env)
    cases = [(mode, "random") for mode in CONTROL_MODES] + [("ee_delta", "expert")]
    for mode, policy_name in cases:
        env = PandaGraspEnv(control_mode=mode, randomization=args.randomization, objects=args.objects)
        PhysicsTimer(env)
        env.reset(seed=int(rng.integers(1 << 31)))
        if policy_name == "expert":
            policy = ScriptedExpert(env.obs_slices)
        else:
            def policy(_obs, n=env.action_dim):
                return rng.uniform(-1, 1, n).astype(np.float32)
        rates, shares, bares = [], [], []
        for _ in range(args.rounds):
            bares.append(bare_rate(bare_env, args.steps))
            rate, share = env_rate(env, args.steps, policy)
            rates.append(rate)
            shares.append(share)
        e, b = statistics.median(rates), statistics.median(bares)
        print(f"{mode:<14}{policy_name:<9}{e:>12.0f}{b:>13.0f}{e / b:>7.2f}"
              f"{statistics.median(shares):>15.2f}", flush=True)
        env.close()


if __name__ == "__main__":
    main()
