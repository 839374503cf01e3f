"""Confidence intervals for success rates and aggregates across seeds."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np


def wilson_interval(successes: int, trials: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval for a binomial rate (95% by default).

    Unlike the normal approximation it stays inside [0, 1] and is sane at 0/n and n/n, which is
    where a good policy's success rate lives.
    """
    if trials <= 0:
        raise ValueError(f"trials must be positive, got {trials}")
    if not 0 <= successes <= trials:
        raise ValueError(f"successes must be in [0, {trials}], got {successes}")
    p = successes / trials
    denom = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    # The exact bounds at 0/n and n/n are 0 and 1; computed, they come out a rounding error short.
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


def trimmed_mean(values: Sequence[float] | np.ndarray, proportion: float = 0.25) -> float:
    """Mean after cutting ``proportion`` of the sorted values from each end (scipy's ``trim_mean``).

    With 0.25 this is the interquartile mean (IQM) that rliable recommends: less sensitive to one
    outlier seed than the mean, less wasteful than the median.
    """
    x = np.sort(np.asarray(values, dtype=float).ravel())
    if x.size == 0:
        raise ValueError("trimmed_mean of an empty sequence")
    cut = int(proportion * x.size)
    return float(x[cut : x.size - cut].mean())


def iqm(values: Sequence[float] | np.ndarray) -> float:
    """Interquartile mean over all values (runs x tasks flattened, as rliable does)."""
    return trimmed_mean(values, 0.25)


def stratified_bootstrap_ci(
    scores: Sequence[float] | np.ndarray,
    statistic: Callable[[np.ndarray], float] = np.mean,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Point estimate and percentile bootstrap interval of ``statistic`` over runs.

    ``scores`` is ``[runs]`` or ``[runs, tasks]``. As in rliable's ``StratifiedBootstrap``, runs are
    resampled with replacement independently within each task (column), so every resample keeps
    every task: with few seeds per task this is the honest interval, not a normal approximation.
    The seeded generator makes the interval reproducible.
    """
    x = np.asarray(scores, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] == 0:
        raise ValueError(f"scores must be [runs] or [runs, tasks] with at least one run, got {x.shape}")
    point = float(statistic(x))
    rng = np.random.default_rng(seed)
    runs, tasks = x.shape
    idx = rng.integers(0, runs, size=(reps, runs, tasks))
    cols = np.arange(tasks)[None, None, :]
    samples = x[idx, cols]  # [reps, runs, tasks], each column resampled within itself
    stats = np.array([statistic(s) for s in samples])
    alpha = (1 - confidence) / 2
    low, high = np.percentile(stats, [100 * alpha, 100 * (1 - alpha)])
    return point, float(low), float(high)
