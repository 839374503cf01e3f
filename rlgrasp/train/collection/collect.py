"""A worker's batch of envs: each collector worker steps one and runs the policy on it.

The policy runs inside the workers, once per step on a whole ``SyncVectorEnv`` of envs: with
TorchRL's ``ParallelEnv`` the policy would run in the parent once per step per env and TorchRL's
per-step cost would dominate the physics. Where the workers run: ``rlgrasp.train.collection.collectors``.
"""

from __future__ import annotations

import functools
import os
import re
import traceback
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import EnvBase, GymWrapper, default_info_dict_reader
from torchrl.envs.transforms import Compose, RewardSum, StepCounter, TransformedEnv

from rlgrasp.envs.factory import EnvFactory
from rlgrasp.utils import die_with_parent

ERROR_FILE_PREFIX = "env_error_"
# Info entries copied into the tensordict (those the env provides).
INFO_DTYPES = {
    "is_success": torch.bool,
    "grasped": torch.bool,
    "lift_height": torch.float32,
    "adr_boundary": torch.int64,  # rlgrasp.adr: the episode's boundary code (ADR runs only)
    "reward_terms": torch.float32,  # each reward term's sum so far this episode (a vector)
}


def _guard(env: Any, name: str, error_dir: str | None) -> Any:
    """Make a failing step/reset leave a report naming the env, then re-raise.

    The process collector only says "At least one process failed: worker N"; the learner reads
    these files to tell the user which env failed and why.
    """
    if error_dir is None:
        return env
    for method in ("step", "reset"):
        original = getattr(env, method)

        def guarded(*args, _original=original, _method=method, **kwargs):
            try:
                return _original(*args, **kwargs)
            except Exception as exc:
                slug = re.sub(r"\W+", "_", name).strip("_")
                path = Path(error_dir) / f"{ERROR_FILE_PREFIX}{slug}.txt"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(
                    f"{name} failed in {_method}: {type(exc).__name__}: {exc}\n\n" + traceback.format_exc()
                )
                raise

        setattr(env, method, guarded)
    return env


class StaggeredStart(gym.Wrapper):
    """Cut the env's first episode short (truncated) at ``first_length`` steps.

    The envs of a worker are reset together and their episodes have one length, so without this
    they stay in phase for the whole run, and a batch of a short-segment layout (32 envs x 16 steps)
    holds the same 16 steps of every episode: the approach in one batch, the lift in another, and
    PPO learned far slower. Staggering the first episodes spreads the phases over every batch.
    Deterministic (no random draw), so the envs' own random streams are unchanged.
    """

    def __init__(self, env: gym.Env, first_length: int):
        super().__init__(env)
        self._cut_at: int | None = first_length
        self._steps = 0

    def reset(self, **kwargs):
        self._steps = 0
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._steps += 1
        if self._cut_at is not None and self._steps >= self._cut_at:
            truncated, self._cut_at = True, None
        return obs, reward, terminated, truncated, info


def _guarded_env(
    make_env: EnvFactory, name: str, error_dir: str | None, index: int = 0, stagger_over: int = 0
) -> Any:
    """One env; with ``stagger_over`` = n > 1, env ``index`` of n ends its first episode after
    (index + 1) / n of the episode length."""
    die_with_parent()  # in a collector's worker process: it must not outlive the learner
    env = _guard(make_env(), name, error_dir)
    length = getattr(env.unwrapped, "max_episode_steps", None)
    if stagger_over > 1 and length:
        first = max(1, round(length * (index + 1) / stagger_over))
        if first < length:
            env = StaggeredStart(env, first)
    return env


class _VectorInfoReader(default_info_dict_reader):
    """TorchRL's info reader, given arrays of one dtype.

    After a partial reset (some envs only) gymnasium's vector infos hold ``None`` for the envs that
    were not reset, an object array TorchRL turns into non-tensor data that then fails to merge
    (``torch.where`` on ``NonTensorData``); those entries are not read anyway (the reset mask
    selects the reset envs), so they become zeros of the key's dtype.
    """

    def __call__(self, info_dict: dict[str, Any], tensordict: TensorDictBase) -> TensorDictBase:
        info_dict = dict(info_dict)
        for key in self.keys:
            value = info_dict.get(key)
            if isinstance(value, np.ndarray) and value.dtype == object:
                dtype = torch.empty((), dtype=INFO_DTYPES[key]).numpy().dtype
                shape = next((np.shape(v) for v in value if v is not None), ())
                info_dict[key] = np.stack(
                    [np.zeros(shape, dtype) if v is None else np.asarray(v, dtype) for v in value]
                )
        return super().__call__(info_dict, tensordict)


def make_vector_env(
    make_env: EnvFactory,
    num_envs: int,
    base_seed: int,
    worker: int,
    error_dir: str | None,
    stagger: bool = False,
) -> EnvBase:
    """``GymWrapper(SyncVectorEnv(...))``: one TensorDict conversion per batch step.

    Autoreset is disabled so that TorchRL resets finished envs itself (``reset_mask``) and the
    final observation of an episode is kept. Vector infos arrive as arrays, which TorchRL's
    ``default_info_dict_reader`` reads directly. ``stagger``: see ``StaggeredStart``.
    """
    fns = [
        functools.partial(
            _guarded_env, make_env, f"worker {worker} env {i}", error_dir, i, num_envs if stagger else 0
        )
        for i in range(num_envs)
    ]
    venv = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.DISABLED)
    _, info = venv.reset(seed=base_seed)
    keys = [k for k in INFO_DTYPES if k in info]
    env = GymWrapper(venv)
    if keys:
        # A vector entry (reward_terms) keeps its length: (num_envs, n).
        shapes = {k: (num_envs, *np.shape(info[k])[1:]) for k in keys}
        spec = Composite({k: Unbounded(shapes[k], dtype=INFO_DTYPES[k]) for k in keys}, shape=(num_envs,))
        env.set_info_dict_reader(_VectorInfoReader(keys, spec=spec))
    env.set_seed(base_seed)  # envs seeded base_seed + i
    return env


def make_batched_env(
    make_env: EnvFactory,
    num_envs: int,
    base_seed: int,
    worker: int = 0,
    torch_threads: int = 1,
    error_dir: str | None = None,
    episode_stats: bool = True,
    seed_torch: bool = True,
    stagger: bool = False,
) -> EnvBase:
    """A batch of ``num_envs`` envs seeded ``base_seed + i``, plus episode return/length.

    Top-level so that spawned workers can unpickle it; it also sets the worker's torch threads and
    seeds the worker's torch RNG (the policy samples actions there).
    """
    torch.set_num_threads(torch_threads)
    if seed_torch:
        torch.manual_seed(base_seed)
    env = make_vector_env(make_env, num_envs, base_seed, worker, error_dir, stagger)
    if episode_stats:
        env = TransformedEnv(env, Compose(RewardSum(), StepCounter()))
    return env


def worker_seed(seed: int, worker: int, generation: int = 0) -> int:
    """Distinct, reproducible seeds: 10,000 apart per worker, shifted on each resume."""
    return int(seed) * 1_000_003 + generation * 100_003 + worker * 10_000


def read_env_errors(error_dir: str | os.PathLike) -> list[str]:
    """First lines of the env error reports written by ``_guard`` (empty if none)."""
    d = Path(error_dir)
    if not d.is_dir():
        return []
    reports = sorted(d.glob(f"{ERROR_FILE_PREFIX}*.txt"))
    return [p.read_text().splitlines()[0] + f"  (full traceback: {p})" for p in reports]
