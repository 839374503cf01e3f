"""Record demonstrations: seeded episodes of the scripted expert (or of a checkpoint's policy) in
worker processes, every step's observation, action and reward kept.

Episode ``i`` is reset with ``seed + i`` and the expert is deterministic, so the file does not depend
on the number of workers (``rlgrasp.evaluation.episodes`` explains why, for evaluation).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict

from rlgrasp.evaluation.policies import PolicySource, build_policy
from rlgrasp.utils import SpawnPool

_WORKER: dict[str, Any] = {}


def _init(source: PolicySource) -> None:
    """One torch thread, one env, one policy per process."""
    torch.set_num_threads(1)
    env = source.make_env()
    _WORKER.update(env=env, actor=build_policy(source, env, deterministic=True))


def record_episode(env: Any, actor: Any, seed: int) -> dict[str, Any]:
    """One episode from ``env.reset(seed=seed)``: its arrays and outcome."""
    obs, info = env.reset(seed=seed)
    actor.reset(seed)
    observations, actions, rewards, next_observations, terminal = [], [], [], [], []
    success = False
    while True:
        action = actor(obs)
        observations.append(np.asarray(obs, np.float32))
        actions.append(np.asarray(action, np.float32))
        obs, reward, terminated, truncated, info = env.step(action)
        rewards.append(float(reward))
        next_observations.append(np.asarray(obs, np.float32))  # an off-policy learner's transitions
        terminal.append(bool(terminated))
        success = bool(info.get("is_success", False))
        if terminated or truncated:
            break
    return {
        "seed": seed,
        "observation": np.stack(observations),
        "action": np.stack(actions),
        "reward": np.asarray(rewards, np.float32),
        "next_observation": np.stack(next_observations),
        "terminated": np.asarray(terminal, np.bool_),
        "length": len(rewards),
        "success": success,
        "object": str(info.get("object", "")),
    }


def _chunk(seeds: Sequence[int]) -> list[dict[str, Any]]:
    return [record_episode(_WORKER["env"], _WORKER["actor"], s) for s in seeds]


def record(
    source: PolicySource,
    episodes: int,
    seed: int,
    workers: int,
    progress: Callable[[int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """``episodes`` episodes seeded ``seed + i`` on ``workers`` processes, in order of ``i``."""
    seeds = [seed + i for i in range(episodes)]
    size = max(1, math.ceil(episodes / (max(workers, 1) * 4)))
    chunks = [seeds[i : i + size] for i in range(0, episodes, size)]
    results: list[dict[str, Any]] = []
    if workers <= 1:
        threads = torch.get_num_threads()
        try:
            _init(source)
            for chunk in chunks:
                results.extend(_chunk(chunk))
                if progress:
                    progress(len(results), episodes)
        finally:
            _WORKER.pop("env").close()
            torch.set_num_threads(threads)
    else:
        # Ctrl-C is the parent's to handle: SpawnPool starts the workers with SIGINT blocked.
        with SpawnPool(min(workers, len(chunks)), _init, (source,)) as pool:
            for chunk_result in pool.imap_unordered(_chunk, chunks):
                results.extend(chunk_result)
                if progress:
                    progress(len(results), episodes)
    return sorted(results, key=lambda e: e["seed"])


def to_frames(episodes: list[dict[str, Any]]) -> TensorDict:
    """The kept episodes as one flat TensorDict of transitions (``done`` marks each episode's last)."""
    parts = []
    for index, e in enumerate(episodes):
        n = e["length"]
        done = torch.zeros(n, dtype=torch.bool)
        done[-1] = True
        parts.append(
            TensorDict(
                {
                    "observation": torch.from_numpy(e["observation"]),
                    "action": torch.from_numpy(e["action"]),
                    "reward": torch.from_numpy(e["reward"]),
                    "next_observation": torch.from_numpy(e["next_observation"]),
                    "terminated": torch.from_numpy(e["terminated"]),
                    "done": done,
                    "episode": torch.full((n,), index, dtype=torch.int64),
                    "success": torch.full((n,), e["success"], dtype=torch.bool),
                },
                batch_size=[n],
            )
        )
    return torch.cat(parts) if parts else TensorDict({}, batch_size=[0])
