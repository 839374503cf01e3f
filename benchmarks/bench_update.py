"""What one PPO update costs the learner, per frame: the ceiling on frames/s however many workers
collect (with ``collector.overlap`` a batch takes about max(collection, update + evaluation)).

    python benchmarks/bench_update.py [--threads 1 2] [--minibatch 512 1024] [--repeats 3] [--compile]
        [overrides ...]

Collects one batch of training's size in-process (default ``experiment=grasp_ppo``), then
times ``PPOLearner.update`` on it for each torch thread count and minibatch size, with the target-KL
stop off so that every update runs all its epochs (training stops some updates early: a bound).
``--compile`` adds a row per setting with the loss under ``torch.compile`` (TorchRL's sota PPO
compiles its update; training here does not): its first update, which compiles, is timed apart.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
import torch

from rlgrasp.compose import compose_train
from rlgrasp.train.collectors import collector_backend
from rlgrasp.train.parts import build_parts
from rlgrasp.train.ppo import PPOLearner


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--minibatch", type=int, nargs="+", default=[512, 1024])
    parser.add_argument("--repeats", type=int, default=3, help="timed updates per setting, after a warm-up")
    parser.add_argument("--compile", action="store_true", help="also time the loss under torch.compile")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides (default experiment=grasp_ppo)")
    args = parser.parse_args()

    cfg = compose_train(args.overrides or ["experiment=grasp_ppo"])
    # One in-process worker collects the batch training would get from all of them.
    frames = collector_backend(cfg.collector).frames_per_batch
    cfg = compose_train([
        *(args.overrides or ["experiment=grasp_ppo"]),
        "collector=single",
        f"collector.steps_per_env={frames // cfg.collector.envs_per_worker}",
    ])
    torch.manual_seed(0)
    collector = build_parts(cfg).make_collector()
    batch = next(iter(collector))
    collector.shutdown()
    frames = batch.numel()
    print(f"{frames:,} frames per batch, {cfg.algo.epochs} epochs, hidden {list(cfg.model.hidden_sizes)}")
    print("| torch threads | minibatch | loss | first update, s | ms per update | ms per frame"
          " | learner ceiling, frames/s |")
    print("|---|---|---|---|---|---|---|")
    for threads in args.threads:
        torch.set_num_threads(threads)
        for minibatch in args.minibatch:
            for compiled in (False, True) if args.compile else (False,):
                algo = copy.deepcopy(cfg.algo)
                algo.minibatch_size, algo.target_kl = minibatch, None
                parts = build_parts(cfg)
                learner = PPOLearner(parts.actor, parts.critic, parts.norm, algo, torch.device("cpu"), True)
                if compiled:
                    learner.loss = torch.compile(learner.loss)
                t0 = time.perf_counter()
                learner.update(batch.clone())  # warm-up; with compile, the compilation
                first = time.perf_counter() - t0
                t0 = time.perf_counter()
                for _ in range(args.repeats):
                    learner.update(batch.clone())
                ms = (time.perf_counter() - t0) / args.repeats * 1000
                row = [threads, minibatch, "compiled" if compiled else "eager", f"{first:.1f}", f"{ms:.0f}",
                       f"{ms / frames:.3f}", f"{frames / ms * 1000:,.0f}"]
                print("| " + " | ".join(map(str, row)) + " |", flush=True)


if __name__ == "__main__":
    main()
