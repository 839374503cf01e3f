"""The loop's counters besides the losses: the episodes a batch finished, frames per second, and
when an interval of frames comes due (evaluation, checkpoints)."""

from __future__ import annotations

import time

import torch
from tensordict import TensorDictBase


class Due:
    """True once every ``interval`` frames (interval <= 0: never)."""

    def __init__(self, interval: int, frames: int) -> None:
        self.interval = interval
        self.mark = frames // interval if interval > 0 else 0

    def __call__(self, frames: int) -> bool:
        if self.interval <= 0 or frames // self.interval <= self.mark:
            return False
        self.mark = frames // self.interval
        return True


class Throughput:
    """Frames/s of this session, measured from the end of the first batch (which includes the
    workers' start-up) on."""

    def __init__(self) -> None:
        self.frames = 0
        self.t0: float | None = None
        self.frames0 = 0

    def __call__(self, new_frames: int, batch_start: float) -> float:
        self.frames += new_frames
        now = time.perf_counter()
        if self.t0 is None:
            self.t0, self.frames0 = now, self.frames
            return new_frames / max(now - batch_start, 1e-9)
        return (self.frames - self.frames0) / max(now - self.t0, 1e-9)


def finished_mask(batch: TensorDictBase, full_length: int | None = None) -> torch.Tensor:
    """Where episodes ended in this batch, without the first episodes ``StaggeredStart`` cut short
    (``collector.stagger_starts``) before ``full_length`` steps: they would not compare like with like."""
    done = batch["next", "done"].reshape(batch.shape)
    keys = batch.keys(True)
    if full_length and ("next", "step_count") in keys and ("next", "truncated") in keys:
        steps = batch["next", "step_count"].reshape(batch.shape)
        done = done & ~(batch["next", "truncated"].reshape(batch.shape) & (steps < full_length))
    return done


def finished_episodes(batch: TensorDictBase, full_length: int | None = None) -> dict[str, float]:
    """Return, length and success-at-episode-end of the episodes that ended in this batch
    (``finished_mask``)."""
    done = finished_mask(batch, full_length)
    keys = batch.keys(True)
    if not done.any():
        return {}
    out = {}
    for key, name in (
        ("episode_reward", "episodic_return"),
        ("step_count", "episodic_length"),
        ("is_success", "success_rate"),
    ):
        if ("next", key) in keys:
            out[f"charts/{name}"] = float(batch["next", key].reshape(batch.shape)[done].float().mean())
    out["charts/episodes"] = float(done.sum())
    return out
