"""Seeded episodes in N worker processes, with results independent of the number of workers.

Why the results do not depend on the worker count:

- every episode ``i`` is reset with its own seed (``base_seed + i``) and the env restores a saved
  physics state on reset, so an episode does not depend on which episodes its worker ran before;
- stochastic actions and the random baseline draw from RNGs re-seeded from the episode's seed;
- the policy sees one observation at a time (no batch-size-dependent kernels) with one torch thread.

Workers are spawned (TorchRL sets ``spawn``) and run the top-level functions below; PyBullet is
connected inside each worker, never inherited.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from rlgrasp.evaluation.outcomes import SUCCESS, failure_reason
from rlgrasp.evaluation.policies import Actor, PolicySource, build_policy
from rlgrasp.evaluation.views import render_frame
from rlgrasp.utils import SpawnPool


@dataclass
class EpisodeResult:
    """One episode: its seed, what was drawn, what happened, and (for video episodes) its frames."""

    index: int
    seed: int
    randomization: dict[str, float]
    episode_return: float
    length: int
    success_at_end: bool
    success_once: bool
    first_success_step: int | None
    grasped_at_end: bool
    max_lift_height: float
    frames: list[np.ndarray] | None = None
    step_success: list[bool] = field(default_factory=list)
    object: str = ""  # e.g. "random_urdfs/140" (envs without objects: "")
    outcome: str = ""  # "success" or the failure reason (rlgrasp.evaluation.outcomes)


def run_episode(env: Any, actor: Actor, index: int, seed: int, render: bool) -> EpisodeResult:
    """One full episode from ``env.reset(seed=seed)`` to termination or the time limit; rendered
    frames show a camera env's view (what the policy acts on next) beside the scene."""
    obs, info = env.reset(seed=seed)
    actor.reset(seed)
    frames = [render_frame(env, obs)] if render else None
    total, steps, first, success, max_lift = 0.0, 0, None, False, 0.0
    # From the reset on, as the env reports them: what failure_reason reads.
    held, tilts = [bool(info.get("grasped", False))], [float(info.get("object_tilt", 0.0))]
    step_success = []
    while True:
        obs, reward, terminated, truncated, info = env.step(actor(obs))
        steps += 1
        total += float(reward)
        success = bool(info.get("is_success", False))
        step_success.append(success)
        if success and first is None:
            first = steps
        max_lift = max(max_lift, float(info.get("lift_height", 0.0)))
        held.append(bool(info.get("grasped", False)))
        tilts.append(float(info.get("object_tilt", 0.0)))
        if render:
            frames.append(render_frame(env, obs))
        if terminated or truncated:
            break
    return EpisodeResult(
        index=index,
        seed=seed,
        randomization={k: float(v) for k, v in (info.get("randomization") or {}).items()},
        episode_return=total,
        length=steps,
        success_at_end=success,
        success_once=first is not None,
        first_success_step=first,
        grasped_at_end=bool(info.get("grasped", False)),
        max_lift_height=max_lift,
        frames=frames,
        step_success=step_success,
        object=str(info.get("object", "")),
        outcome=_outcome(success, held, tilts, info),
    )


def _outcome(success: bool, held: list[bool], tilts: list[float], info: dict[str, Any]) -> str:
    if success:
        return SUCCESS
    return failure_reason(held, tilts, info.get("object_extents", (0.0, 0.0, 0.0)))


# --- worker processes -------------------------------------------------------------------------
_WORKER: dict[str, Any] = {}


def _init_worker(source: PolicySource, deterministic: bool, video_episodes: int) -> None:
    """Per-process set-up: one torch thread, one env (own PyBullet client), one policy."""
    torch.set_num_threads(1)
    env = source.make_env()
    _WORKER.update(env=env, actor=build_policy(source, env, deterministic), video_episodes=video_episodes)


def _run_chunk(jobs: Sequence[tuple[int, int]]) -> list[EpisodeResult]:
    env, actor, k = _WORKER["env"], _WORKER["actor"], _WORKER["video_episodes"]
    return [run_episode(env, actor, i, seed, render=i < k) for i, seed in jobs]


def _close_worker() -> None:
    env = _WORKER.pop("env", None)
    if env is not None:
        env.close()
    _WORKER.clear()


def episode_seeds(base_seed: int, episodes: int) -> list[int]:
    """Episode ``i`` is reset with ``base_seed + i``."""
    return [int(base_seed) + i for i in range(int(episodes))]


def run_episodes(
    source: PolicySource,
    episodes: int,
    base_seed: int,
    workers: int = 1,
    deterministic: bool = True,
    video_episodes: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> list[EpisodeResult]:
    """Run ``episodes`` seeded episodes on ``workers`` processes (1 = in this process), in order."""
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    jobs = list(enumerate(episode_seeds(base_seed, episodes)))
    workers = min(workers, episodes)
    # Rendered episodes cost ~30x more: one chunk each, first, so that workers share them. Small
    # chunks of the rest balance the load at low overhead.
    k = min(video_episodes, episodes)
    size = max(1, math.ceil((episodes - k) / (workers * 4)))
    chunks = [[j] for j in jobs[:k]] + [jobs[i : i + size] for i in range(k, len(jobs), size)]
    results: list[EpisodeResult] = []
    if workers == 1:
        threads = torch.get_num_threads()
        try:
            with torch.random.fork_rng():
                _init_worker(source, deterministic, video_episodes)
                for chunk in chunks:
                    results.extend(_run_chunk(chunk))
                    if progress:
                        progress(len(results), episodes)
        finally:
            _close_worker()
            torch.set_num_threads(threads)
    else:
        # The parent handles Ctrl-C and terminates the pool (SpawnPool starts it with SIGINT blocked).
        with SpawnPool(workers, _init_worker, (source, deterministic, video_episodes)) as pool:
            for chunk_result in pool.imap_unordered(_run_chunk, chunks):
                results.extend(chunk_result)
                if progress:
                    progress(len(results), episodes)
    results.sort(key=lambda r: r.index)
    return results


def timed_run(**kwargs: Any) -> tuple[list[EpisodeResult], float]:
    """``run_episodes`` and its wall-clock seconds."""
    start = time.perf_counter()
    results = run_episodes(**kwargs)
    return results, time.perf_counter() - start
