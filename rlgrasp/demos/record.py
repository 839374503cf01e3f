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


#: A camera env's observation entries under the names a TorchRL tensordict gives them (``state`` is
#: the gym wrapper's ``observation``); the state env's flat vector is ``observation`` too.
ENTRY_NAMES = {"state": "observation"}


def _entries(obs: Any) -> dict[str, np.ndarray]:
    """An observation as named arrays: a camera env's dict entry by entry (images in their own
    dtype), a state env's vector as ``observation``."""
    if isinstance(obs, dict):
        return {ENTRY_NAMES.get(k, k): np.asarray(v) for k, v in obs.items()}
    return {"observation": np.asarray(obs, np.float32)}


def record_episode(env: Any, actor: Any, seed: int) -> dict[str, Any]:
    """One episode from ``env.reset(seed=seed)``: its arrays and outcome. Each observation entry
    ``k`` (``observation``; with a camera also the images and ``privileged``) comes with
    ``next_<k>``, the step's successor, for an off-policy learner's transitions."""
    obs, info = env.reset(seed=seed)
    actor.reset(seed)
    steps: dict[str, list[np.ndarray]] = {}
    actions, rewards, terminal = [], [], []
    success = False
    while True:
        action = actor(obs)
        for key, value in _entries(obs).items():
            steps.setdefault(key, []).append(value)
        actions.append(np.asarray(action, np.float32))
        obs, reward, terminated, truncated, info = env.step(action)
        rewards.append(float(reward))
        for key, value in _entries(obs).items():
            steps.setdefault(f"next_{key}", []).append(value)
        terminal.append(bool(terminated))
        success = bool(info.get("is_success", False))
        if terminated or truncated:
            break
    return {
        "seed": seed,
        **{key: np.stack(values) for key, values in steps.items()},
        "action": np.stack(actions),
        "reward": np.asarray(rewards, np.float32),
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
        arrays = {k: torch.from_numpy(v) for k, v in e.items() if isinstance(v, np.ndarray)}
        parts.append(
            TensorDict(
                {
                    **arrays,  # observation entries and their next_, action, reward, terminated
                    "done": done,
                    "episode": torch.full((n,), index, dtype=torch.int64),
                    "success": torch.full((n,), e["success"], dtype=torch.bool),
                },
                batch_size=[n],
            )
        )
    return torch.cat(parts) if parts else TensorDict({}, batch_size=[0])
