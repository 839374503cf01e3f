"""Env steps/s of PandaGraspEnv per control mode against bare PyBullet stepping of the same scene.

Measured in one process, interleaved in rounds so that background load hits both alike; each figure
is the median over rounds. Bare stepping = the same scene after a reset (arm holding its pose under
position control, object at rest), ``substeps`` calls to ``stepSimulation`` per env step. Because a
moving arm makes contacts that an idle one does not, the table also gives the share of env time
spent inside ``stepSimulation`` during the env run: 1 - that share is the env's own overhead.

    python benchmarks/bench_env.py [--steps 1000] [--rounds 5] [--randomization default] [--objects cube]
        [--modes ee_delta ...] [--collision-model mesh|primitive] [--cpu-time]

``--cpu-time`` times with the process's CPU clock instead of the wall clock: on a shared machine
(or at ``nice -n 19``) the wall clock counts the time other processes held the core.

``--record PAGE/ID`` writes each mode's ratio to bare stepping into that row of
docs/benchmarks/results.json and its page's table (benchmarks/results_file.py), met when every one
is >= ``--target``:

    python benchmarks/bench_env.py --steps 1000 --rounds 3 --modes ee_delta joint_delta joint_torque \
        --record throughput/env-step --target 0.8
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

from rlgrasp.envs import CONTROL_MODES, PandaGraspEnv, ScriptedExpert

clock = time.perf_counter  # --cpu-time: time.process_time


class PhysicsTimer:
    """Wraps a client's stepSimulation to add up the time spent in it."""

    def __init__(self, env: PandaGraspEnv):
        self.seconds = 0.0
        self._step = env.client.stepSimulation
        env.client.stepSimulation = self  # an instance attribute wins over BulletClient.__getattr__

    def __call__(self):
        start = clock()
        self._step()
        self.seconds += clock() - start


def env_rate(env: PandaGraspEnv, steps: int, policy) -> tuple[float, float]:
    """(steps/s, share of the time inside stepSimulation)."""
    timer = env.client.stepSimulation
    timer.seconds = 0.0
    obs, _ = env.reset()
    start = clock()
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(policy(obs))
        if terminated or truncated:
            obs, _ = env.reset()
            getattr(policy, "reset", lambda: None)()
    elapsed = clock() - start
    return steps / elapsed, timer.seconds / elapsed


def bare_rate(env: PandaGraspEnv, steps: int) -> float:
    env.reset(seed=0)
    step = env.client.stepSimulation._step
    start = clock()
    for _ in range(steps * env.sim.substeps):
        step()
    return steps / (clock() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--randomization", default="default")
    parser.add_argument("--objects", default="cube", help="object set (rlgrasp.envs.objects)")
    parser.add_argument(
        "--modes",
        nargs="+",
        default=list(CONTROL_MODES) + ["expert"],
        help="control modes (random actions) and/or expert (ee_delta, scripted expert)",
    )
    parser.add_argument("--collision-model", default="mesh", choices=["mesh", "primitive"])
    parser.add_argument("--cpu-time", action="store_true", help="time with the process's CPU clock")
    results_file.add_options(parser)
    parser.add_argument("--target", type=float, help="with --record: the ratio every mode must reach")
    args = parser.parse_args()
    global clock
    clock = time.process_time if args.cpu_time else time.perf_counter
    scene = dict(randomization=args.randomization, objects=args.objects)
    if args.collision_model != "mesh":  # the default unnamed: the script runs on env code before the option
        scene["collision_model"] = args.collision_model

    rng = np.random.default_rng(0)
    print(
        f"randomization={args.randomization}  objects={args.objects}  "
        f"collision_model={args.collision_model}  steps/round={args.steps}  rounds={args.rounds}  "
        f"clock={'cpu' if args.cpu_time else 'wall'}"
    )
    print(
        f"{'control_mode':<14}{'policy':<9}{'env steps/s':>12}{'bare steps/s':>13}{'ratio':>7}"
        f"{'physics share':>15}{'other ms/step':>15}"
    )
    bare_env = PandaGraspEnv(**scene)
    PhysicsTimer(bare_env)
    cases = [("ee_delta", "expert") if m == "expert" else (m, "random") for m in args.modes]
    ratios = {}
    for mode, policy_name in cases:
        env = PandaGraspEnv(**scene, control={"mode": mode})
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
        e, b, share = statistics.median(rates), statistics.median(bares), statistics.median(shares)
        print(
            f"{mode:<14}{policy_name:<9}{e:>12.0f}{b:>13.0f}{e / b:>7.2f}"
            f"{share:>15.2f}{(1 - share) / e * 1e3:>15.3f}",
            flush=True,
        )
        env.close()
        ratios[mode if policy_name == "random" else f"{mode} {policy_name}"] = e / b
    if args.record:
        met = (
            "see page"
            if args.target is None
            else results_file.met_of([r >= args.target for r in ratios.values()])
        )
        results_file.record(*args.record, record_text(ratios), met, load=args.record_load)


def record_text(ratios: dict[str, float]) -> str:
    """The results table's ``measured`` cell: env steps/s as a share of bare stepping per mode, in
    the pages' form "0.64 / 0.72 (`ee_delta` / `joint_delta`)"."""
    values = " / ".join(f"{r:.2f}" for r in ratios.values())
    return f"{values} ({' / '.join(f'`{m}`' for m in ratios)})"


if __name__ == "__main__":
    main()
