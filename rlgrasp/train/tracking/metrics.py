"""The loop's counters besides the losses: the episodes a batch finished, frames per second, when
an interval of frames comes due (evaluation, checkpoints), and where a run's wall clock went."""

from __future__ import annotations

import contextlib
import os
import re
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

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


def process_age_s() -> float:
    """Seconds since this process was launched (Linux: ``/proc``), so start-up before any of our code
    ran (the interpreter, imports) is counted; elsewhere 0."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22: clock ticks after boot
        return max(0.0, float(Path("/proc/uptime").read_text().split()[0]) - started)
    except (OSError, ValueError, IndexError):
        return 0.0


class Phases:
    """Wall-clock seconds per phase of a run (``with phases("update"): ...``). A phase entered inside
    another is taken out of the outer one's time, so the phases add up to the time they cover; the
    time since launch that no phase covers is ``other``."""

    def __init__(self) -> None:
        self.launched = time.perf_counter() - process_age_s()
        self.seconds: dict[str, float] = {}
        self._inner: list[float] = []  # the time of the phases entered inside each open one

    @contextlib.contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        self._inner.append(0.0)
        try:
            yield
        finally:
            elapsed = time.perf_counter() - t0
            inner = self._inner.pop()
            self.seconds[name] = self.seconds.get(name, 0.0) + elapsed - inner
            if self._inner:
                self._inner[-1] += elapsed

    def mark(self, name: str) -> None:
        """Charge the time from launch up to now that no phase covers to ``name`` (the start-up)."""
        uncovered = max(0.0, self.since_launch() - sum(self.seconds.values()))
        self.seconds[name] = self.seconds.get(name, 0.0) + uncovered

    def since_launch(self) -> float:
        return time.perf_counter() - self.launched

    def line(self) -> str:
        """``time from launch T s: a X s, b Y s, ..., other Z s`` (``parse_phases`` reads it back)."""
        total = self.since_launch()
        parts = [f"{name} {s:.1f} s" for name, s in self.seconds.items()]
        parts.append(f"other {max(0.0, total - sum(self.seconds.values())):.1f} s")
        return f"time from launch {total:.1f} s: " + ", ".join(parts)


def parse_phases(line: str) -> dict[str, float]:
    """``Phases.line``'s figures: ``{"total": T, name: seconds, ...}``."""
    total = re.search(r"time from launch ([\d.]+) s", line)
    out = {"total": float(total.group(1))} if total else {}
    tail = line.split(": ", 1)[-1] if total else ""
    out.update({m.group(1): float(m.group(2)) for m in re.finditer(r"([a-z][a-z ,'-]*?) ([\d.]+) s", tail)})
    return out


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


def finished_episodes(
    batch: TensorDictBase, full_length: int | None = None, reward_terms: Sequence[str] = ()
) -> dict[str, float]:
    """Return, length and success-at-episode-end of the episodes that ended in this batch
    (``finished_mask``), and each reward term's mean episode sum (``rewards/<term>``: which term
    drives learning)."""
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
    if reward_terms and ("next", "reward_terms") in keys:
        sums = batch["next", "reward_terms"].reshape(*batch.shape, -1)[done].float().mean(0)
        out.update({f"rewards/{name}": float(value) for name, value in zip(reward_terms, sums)})
    return out
