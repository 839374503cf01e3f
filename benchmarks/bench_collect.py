"""Collection throughput, side by side: raw env vs gymnasium AsyncVectorEnv vs rlgrasp's collector.

    python benchmarks/bench_collect.py [--seconds 20] [--train-frames 20480] [hydra overrides ...]

1. raw: one process per core, each stepping one env with random actions in a plain gymnasium loop
   (no torch in the loop) -- the ceiling for this machine;
2. gymnasium ``AsyncVectorEnv`` over the same number of envs the collector uses;
3. rlgrasp's collector (``collector.*`` config) with the PPO actor, policy run inside the workers;
4. optionally end-to-end training SPS (collection plus PPO updates), ``--train-frames`` frames,
   once with ``collector.overlap=false`` (workers idle while the learner updates) and once with
   ``collector.overlap=true`` (they collect the next batch meanwhile), one after the other.

Prints frames/s and the ratios to raw (targets: collector >= 0.85, end to end >= 0.75).
``--record PAGE/ID`` writes the collector's ratio into that row of docs/benchmarks/results.json and
its page's table (benchmarks/results_file.py), ``--record-end-to-end PAGE/ID`` the end-to-end one
(with ``--train-frames``), each met against its target above:

    python benchmarks/bench_collect.py --train-frames 20480 --record throughput/collector \
        --record-end-to-end throughput/end-to-end experiment=grasp_ppo
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
sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_file, also when loaded by path
import gymnasium as gym
import results_file
import torch
from omegaconf import OmegaConf
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from rlgrasp.compose import compose_train
from rlgrasp.envs.factory import env_factory
from rlgrasp.train.loop import train
from rlgrasp.train.parts import build_parts


def _raw_worker(make_env, seconds: float, seed: int, out: mp.Queue) -> None:
    env = make_env()
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


def bench_raw(make_env, seconds: float, procs: int) -> float:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    ps = [ctx.Process(target=_raw_worker, args=(make_env, seconds, i, q)) for i in range(procs)]
    for p in ps:
        p.start()
    rates = [q.get() for _ in ps]
    for p in ps:
        p.join()
    return sum(rates)


def bench_async(make_env, seconds: float, num_envs: int) -> float:
    envs = gym.vector.AsyncVectorEnv([make_env] * num_envs, context="spawn")
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
    torch.set_num_threads(cfg.collector.torch_threads)
    parts = build_parts(cfg)
    collector = parts.make_collector()
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
    with tempfile.TemporaryDirectory() as tmp:
        cfg = compose_train(
            [
                *overrides,
                f"paths.output_dir={tmp}",
                f"total_frames={frames}",
                "eval.interval_frames=0",
                "checkpoint.interval_frames=0",
                "eval.episodes=1",
                "eval.final_episodes=1",
                "eval.num_envs=1",
            ]
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
    results_file.add_options(parser)
    parser.add_argument(
        "--record-end-to-end",
        type=results_file.row_spec,
        metavar="PAGE/ID",
        help="with --train-frames: the row the end-to-end ratio is written into",
    )
    args = parser.parse_args()
    if args.record_end_to_end and not args.train_frames:
        parser.error("--record-end-to-end needs --train-frames")

    overrides = args.overrides or ["experiment=grasp_ppo"]
    cfg = compose_train([*overrides, "paths.output_dir=/tmp/unused"])
    make_env = env_factory(cfg.env)
    c = cfg.collector
    num_envs = max(c.num_workers, 1) * c.envs_per_worker

    print(f"env: {OmegaConf.to_container(cfg.env, resolve=True)}")
    print(f"collector: {dict(c)}  ({num_envs} envs)")

    def row(label: str, rate: float) -> None:
        print(f"{label:<52} {rate:9,.0f} frames/s  ({rate / raw:.2f} of raw)")

    raw = bench_raw(make_env, args.seconds, args.procs)
    row(f"raw env, {args.procs} processes x 1 env, random actions", raw)
    row(f"gymnasium AsyncVectorEnv, {num_envs} envs", bench_async(make_env, args.seconds, num_envs))
    col = bench_collector(cfg, args.seconds)
    row("rlgrasp collector + PPO actor", col)
    print(f"ratio collector/raw = {col / raw:.2f} (target >= {COLLECTOR_TARGET})")
    if args.record:
        met = results_file.met_of([col / raw >= COLLECTOR_TARGET])
        results_file.record(*args.record, ratio_text(col, raw), met, load=args.record_load)
    if args.train_frames:
        sps = {}
        for overlap in ("false", "true"):
            sps[overlap] = bench_train([*overrides, f"collector.overlap={overlap}"], args.train_frames)
            row(f"end-to-end training, overlap={overlap} ({args.train_frames:,} frames)", sps[overlap])
        print(
            f"end to end: overlap/no overlap = {sps['true'] / sps['false']:.2f}; "
            f"best/raw = {max(sps.values()) / raw:.2f} (target >= {END_TO_END_TARGET})"
        )
        if args.record_end_to_end:
            best = max(sps.values())
            results_file.record(
                *args.record_end_to_end,
                ratio_text(best, raw),
                results_file.met_of([best / raw >= END_TO_END_TARGET]),
                load=args.record_load,
            )


COLLECTOR_TARGET, END_TO_END_TARGET = 0.85, 0.75  # shares of raw stepping: docs/benchmarks/throughput.md


def ratio_text(rate: float, raw: float) -> str:
    """The results table's ``measured`` cell: a rate as a share of raw stepping, with both frames/s."""
    return f"{rate / raw:.2f} ({rate:,.0f} against {raw:,.0f} raw frames/s)"


if __name__ == "__main__":
    main()
