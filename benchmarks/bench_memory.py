"""What an off-policy run holds in memory: its replay buffer filled to ``algo.replay.buffer_frames``,
against the estimate the run checks before it starts, and the run's processes together.

    python benchmarks/bench_memory.py experiment=grasp_vision_sac
    python benchmarks/bench_memory.py experiment=grasp_vision_sac_demos

Filling the buffer by training takes the run's whole length (over an hour for grasp_vision_sac), so
this fills it in a few minutes: it collects one batch in-process and stores it again and again
through ``SAC.store``, as training does, until the buffer is full. The learner's resident memory is
read from ``/proc`` before and after (the storage's pages count once written). Then the run's
collector starts its workers and steps a few batches, and the workers' resident memory is added: the
total is what the run's processes hold at the end of a run, the figure set against the 8 GiB target
of docs/history/algorithms.md. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
import torch
from bench_update import collect

from rlgrasp.algos.sac import SAC, replay_bytes_per_frame
from rlgrasp.compose import compose_train
from rlgrasp.train.parts import build_parts

GIB = 2**30


def resident_bytes(pid: int | str = "self", field: str = "VmRSS") -> int:
    """A process's resident memory (``VmRSS``) or its peak (``VmHWM``), from ``/proc``."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) * 1024
    return 0


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (the collector's workers and whatever they started)."""
    out, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").iterdir():
            children = [int(c) for c in (task / "children").read_text().split()]
            out += children
            todo += children
    return out


def fill_replay(overrides: list[str], batch_frames: int) -> tuple[SAC, int, int]:
    """A learner whose replay buffer is full; returns it, the learner's resident bytes before the
    first frame was stored, and the frames stored."""
    cfg, batch = collect(overrides, batch_frames)
    algo = SAC(cfg, build_parts(cfg), torch.device("cpu"))
    flat = batch.reshape(-1)
    before = resident_bytes()
    frames = 0
    while frames < cfg.algo.replay.buffer_frames:
        algo.store(flat)
        frames += flat.numel()
    return algo, before, min(frames, cfg.algo.replay.buffer_frames)


def workers_bytes(overrides: list[str], batches: int) -> tuple[int, int]:
    """The resident bytes of the run's collector workers after ``batches`` batches, and how many."""
    collector = build_parts(compose_train(overrides)).make_collector()
    try:
        for i, _ in enumerate(collector):
            if i + 1 >= batches:
                break
        pids = descendants(os.getpid())
        return sum(resident_bytes(p) for p in pids), len(pids)
    finally:
        collector.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--batch-frames", type=int, default=1024, help="frames collected, stored again and again"
    )
    parser.add_argument("--batches", type=int, default=3, help="batches before the workers are read")
    parser.add_argument("overrides", nargs="+", help="Hydra overrides, e.g. experiment=grasp_vision_sac")
    args = parser.parse_args()

    algo, before, frames = fill_replay(args.overrides, args.batch_frames)
    learner = resident_bytes()
    estimate = frames * replay_bytes_per_frame(algo.parts.spec, algo.transition_keys)
    measured = learner - before
    print(
        f"replay: {frames:,} frames; estimate {estimate / GIB:.2f} GiB, measured {measured / GIB:.2f} GiB "
        f"({measured / max(estimate, 1):.2f} x the estimate)"
    )
    print(f"learner: {learner / GIB:.2f} GiB resident (peak {resident_bytes(field='VmHWM') / GIB:.2f} GiB)")
    workers, count = workers_bytes(args.overrides, args.batches)
    print(f"workers: {workers / GIB:.2f} GiB resident in {count} processes")
    print(f"run: {(learner + workers) / GIB:.2f} GiB resident in all")


if __name__ == "__main__":
    main()
