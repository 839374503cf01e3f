"""Where a collector worker's time goes: one process, one batch of envs and the PPO actor under
TorchRL's ``Collector``, profiled with cProfile, then a plain ``env.step`` loop for comparison.

    python benchmarks/profile_worker.py [--envs 8] [--batches 8] [--top 30] [hydra overrides ...]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
import torch
from torchrl.collectors import Collector

from rlgrasp.compose import compose_train
from rlgrasp.train.collection.collect import make_batched_env
from rlgrasp.train.parts import build_parts


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", type=int, default=8, help="envs in the worker's SyncVectorEnv")
    parser.add_argument("--batches", type=int, default=8, help="64-step batches profiled")
    parser.add_argument("--top", type=int, default=30, help="functions printed, by cumulative time")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides (default experiment=grasp_ppo)")
    args = parser.parse_args()

    cfg = compose_train([*(args.overrides or ["experiment=grasp_ppo"]), "paths.output_dir=/tmp/unused"])
    torch.manual_seed(0)
    torch.set_num_threads(1)
    parts = build_parts(cfg)
    env = make_batched_env(parts.make_env, args.envs, 0)
    collector = Collector(
        env,
        parts.actor,
        frames_per_batch=args.envs * 64,
        total_frames=-1,
        auto_register_policy_transforms=False,
    )
    batches = iter(collector)
    next(batches)  # warm-up
    profiler, frames, start = cProfile.Profile(), 0, time.perf_counter()
    profiler.enable()
    for _ in range(args.batches):
        frames += next(batches).numel()
    profiler.disable()
    rate = frames / (time.perf_counter() - start)
    print(f"collector, 1 process, {args.envs} envs (profiled): {rate:,.0f} frames/s")
    pstats.Stats(profiler).sort_stats("cumtime").print_stats(args.top)
    collector.shutdown()

    plain = parts.make_env()
    plain.reset(seed=0)
    start = time.perf_counter()
    for _ in range(2000):
        _, _, terminated, truncated, _ = plain.step(plain.action_space.sample())
        if terminated or truncated:
            plain.reset()
    print(f"plain env.step loop, random actions: {2000 / (time.perf_counter() - start):,.0f} frames/s")


if __name__ == "__main__":
    main()
