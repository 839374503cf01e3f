"""Collection throughput, side by side: raw env vs gymnasium AsyncVectorEnv vs rlgrasp's collector.

    python scripts/bench_collect.py [--seconds 20] [--train-frames 20480] [hydra overrides ...]

1. raw: one process per core, each stepping one env with random actions in a plain gymnasium loop
   (no torch in the loop) -- the ceiling for this machine;
2. gymnasium ``AsyncVectorEnv`` over the same number of envs the collector uses;
3. rlgrasp's collector (``collector.*`` config) with the PPO actor, policy run inside the workers;
4. optionally end-to-end training SPS (collection plus PPO updates), ``--train-frames`` frames.

Prints frames/s and the ratio collector/raw (target >= 0.8).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled

CONFIG_DIR = str(Path(__file__).resolve().parents[1] / "configs")


def _gym_env(env_cfg: dict):
    from rlgrasp.envs.panda_grasp import PandaGraspEnv
    from rlgrasp.train.collect import env_kwargs

    return PandaGraspEnv(**env_kwargs(env_cfg))


def _raw_worker(env_cfg: dict, seconds: float, seed: int, out: mp.Queue) -> None:
    env = _gym_env(env_cfg)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for _ in range(50):  # warm-up
        env.step(env.action_space.sample())
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        n += 1
        if term or trunc:
            env.reset()
    out.put(n / (time.perf_counter() - t0))


def bench_raw(env_cfg: dict, seconds: float, procs: int) -> float:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    ps = [ctx.Process(target=_raw_worker, args=(env_cfg, seconds, i, q)) for i in range(procs)]
    for p in ps:
        p.start()
    rates = [q.get() for _ in ps]
    for p in ps:
        p.join()
    return sum(rates)


def _make_gym_env(env_cfg: dict):
    return _gym_env(env_cfg)


def bench_async(env_cfg: dict, seconds: float, num_envs: int) -> float:
    import functools

    import gymnasium as gym

    envs = gym.vector.AsyncVectorEnv(
        [functools.partial(_make_gym_env, env_cfg) for _ in range(num_envs)], context="spawn"
    )
    envs.reset(seed=0)
    for _ in range(20):
        envs.step(envs.action_space.sample())
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        envs.step(envs.action_space.sample())
        n += num_envs
    rate = n / (time.perf_counter() - t0)
    envs.close()
    return rate


def bench_collector(cfg, seconds: float) -> float:
    import torch

    from rlgrasp.train.collect import build_collector
    from rlgrasp.train.loop import _env_spec, frames_per_batch
    from rlgrasp.train.models import build_models

    torch.set_num_threads(cfg.collector.torch_threads)
    spec = _env_spec(dict(cfg.env), cfg.collector.vector)
    actor, _, _ = build_models(
        spec["obs_dim"], torch.tensor(spec["action_low"]), torch.tensor(spec["action_high"]), cfg.model
    )
    fpb = frames_per_batch(cfg)
    with tempfile.TemporaryDirectory() as tmp:
        collector = build_collector(cfg, actor, fpb, 0, tmp)
        it = iter(collector)
        next(it)  # start-up and warm-up
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            n += next(it).numel()
            collector.update_policy_weights_()
        rate = n / (time.perf_counter() - t0)
        collector.shutdown()
    return rate


def bench_train(overrides: list[str], frames: int) -> float:
    from hydra import compose, initialize_config_dir
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from rlgrasp.train.loop import train

    with tempfile.TemporaryDirectory() as tmp, initialize_config_dir(CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "train",
            overrides=[
                *overrides,
                f"paths.output_dir={tmp}",
                f"total_frames={frames}",
                "eval.interval_frames=0",
                "checkpoint.interval_frames=0",
                "eval.episodes=1",
                "eval.final_episodes=1",
                "eval.num_envs=1",
            ],
        )
        train(cfg)
        acc = EventAccumulator(str(Path(tmp) / "tensorboard"), size_guidance={"scalars": 0})
        acc.Reload()
        return acc.Scalars("charts/SPS")[-1].value


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=20.0, help="measuring time per set-up")
    parser.add_argument("--procs", type=int, default=os.cpu_count(), help="raw processes (cores)")
    parser.add_argument("--train-frames", type=int, default=0, help="also train this many frames")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. experiment=grasp_ppo")
    args = parser.parse_args()

    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from rlgrasp.train.config import register_configs

    register_configs()
    overrides = args.overrides or ["experiment=grasp_ppo"]
    with initialize_config_dir(CONFIG_DIR, version_base="1.3"):
        cfg = compose("train", overrides=[*overrides, "paths.output_dir=/tmp/unused"])
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    c = cfg.collector
    num_envs = max(c.num_workers, 1) * c.envs_per_worker

    print(f"env: {env_cfg}")
    print(f"collector: {dict(c)}  ({num_envs} envs)")

    def row(label: str, rate: float) -> None:
        print(f"{label:<52} {rate:9,.0f} frames/s  ({rate / raw:.2f} of raw)")

    raw = bench_raw(env_cfg, args.seconds, args.procs)
    row(f"raw env, {args.procs} processes x 1 env, random actions", raw)
    row(f"gymnasium AsyncVectorEnv, {num_envs} envs", bench_async(env_cfg, args.seconds, num_envs))
    col = bench_collector(cfg, args.seconds)
    row(f"rlgrasp collector ({c.vector}) + PPO actor", col)
    print(f"ratio collector/raw = {col / raw:.2f} (target >= 0.8)")
    if args.train_frames:
        sps = bench_train(overrides, args.train_frames)
        print(f"end-to-end training SPS ({args.train_frames:,} frames): {sps:,.0f} ({sps / raw:.2f} of raw)")


if __name__ == "__main__":
    main()
