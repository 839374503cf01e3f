"""Env factories and the collector: each worker steps a batch of envs and runs the policy on it.

RESEARCH.md section 3: with ParallelEnv the policy runs in the parent once per step and TorchRL's
per-step cost dominates; a process collector whose workers each own a ``SerialEnv`` of several envs
and call the actor once per batch gets close to raw physics speed.
"""

from __future__ import annotations

import functools
import importlib
import os
import traceback
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import torch
from torchrl.collectors import BaseCollector, Collector
from torchrl.envs import EnvBase, SerialEnv
from torchrl.envs.transforms import Compose, RewardSum, StepCounter, TransformedEnv

ERROR_FILE_PREFIX = "env_error_"


def resolve_factory(spec: str) -> Callable[..., EnvBase]:
    """Import ``"package.module:function"``."""
    module_name, _, attr = spec.partition(":")
    if not attr:
        raise ValueError(f"env.factory must look like 'package.module:function', got {spec!r}")
    return getattr(importlib.import_module(module_name), attr)


def env_kwargs(env_cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The factory's keyword arguments: every ``env`` field except ``factory``, ``kwargs`` merged in."""
    kwargs = {k: v for k, v in env_cfg.items() if k not in ("factory", "kwargs")}
    kwargs.update(env_cfg.get("kwargs") or {})
    return kwargs


def _guard(env: EnvBase, name: str, error_dir: str | None) -> EnvBase:
    """Make a failing step/reset leave a report naming the env, then re-raise.

    The process collector only says "At least one process failed: worker N"; the learner reads
    these files to tell the user which env failed and why. Instance attributes shadow the bound
    methods that ``SerialEnv`` calls on each sub-env (``_step``/``_reset``).
    """
    if error_dir is None:
        return env
    for method in ("_step", "_reset"):
        original = getattr(env, method)

        def guarded(*args, _original=original, _method=method, **kwargs):
            try:
                return _original(*args, **kwargs)
            except Exception as exc:
                path = Path(error_dir) / f"{ERROR_FILE_PREFIX}{name.replace(' ', '_')}.txt"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(
                    f"{name} failed in {_method.lstrip('_')}: {type(exc).__name__}: {exc}\n\n"
                    + traceback.format_exc()
                )
                raise

        setattr(env, method, guarded)
    return env


def make_env(
    env_cfg: Mapping[str, Any],
    seed: int | None = None,
    name: str = "env",
    error_dir: str | None = None,
) -> EnvBase:
    """One env from the configured factory, seeded (its first reset uses ``seed``)."""
    env = resolve_factory(env_cfg["factory"])(**env_kwargs(env_cfg))
    if seed is not None:
        env.set_seed(seed)
    return _guard(env, f"{name} (seed {seed})", error_dir)


def make_batched_env(
    env_cfg: Mapping[str, Any],
    num_envs: int,
    base_seed: int,
    worker: int = 0,
    torch_threads: int = 1,
    error_dir: str | None = None,
    episode_stats: bool = True,
    seed_torch: bool = True,
) -> EnvBase:
    """A ``SerialEnv`` of ``num_envs`` envs seeded ``base_seed + i``, plus episode return/length.

    Top-level so that spawned workers can unpickle it; it also sets the worker's torch threads and
    seeds the worker's torch RNG (the policy samples actions there).
    """
    torch.set_num_threads(torch_threads)
    if seed_torch:
        torch.manual_seed(base_seed)
    fns = [
        functools.partial(
            make_env, env_cfg, base_seed + i, f"worker {worker} env {i}", error_dir
        )
        for i in range(num_envs)
    ]
    env = SerialEnv(num_envs, fns)
    if episode_stats:
        env = TransformedEnv(env, Compose(RewardSum(), StepCounter()))
    return env


def worker_seed(seed: int, worker: int, generation: int = 0) -> int:
    """Distinct, reproducible seeds: 10,000 apart per worker, shifted on each resume."""
    return int(seed) * 1_000_003 + generation * 100_003 + worker * 10_000


def build_collector(
    cfg: Any, policy: torch.nn.Module, frames_per_batch: int, generation: int, error_dir: str
) -> BaseCollector:
    """A synchronous TorchRL collector over ``num_workers`` processes (or in-process)."""
    c = cfg.collector
    env_cfg = dict(cfg.env)
    in_process = c.backend == "single" or c.num_workers == 0
    common = {
        "frames_per_batch": frames_per_batch,
        "total_frames": -1,
        "auto_register_policy_transforms": False,
    }
    if in_process:
        env = make_batched_env(
            env_cfg,
            c.envs_per_worker,
            worker_seed(cfg.seed, 0, generation),
            0,
            torch.get_num_threads(),
            error_dir,
        )
        return Collector(env, policy, **common)
    if c.backend != "process":
        raise ValueError(f"collector.backend must be 'process' or 'single', got {c.backend!r}")
    fns = [
        functools.partial(
            make_batched_env,
            env_cfg,
            c.envs_per_worker,
            worker_seed(cfg.seed, w, generation),
            w,
            c.torch_threads,
            error_dir,
        )
        for w in range(c.num_workers)
    ]
    return Collector(fns, policy, num_collectors=c.num_workers, sync=True, backend="process", **common)


def read_env_errors(error_dir: str | os.PathLike) -> list[str]:
    """First lines of the env error reports written by ``_guard`` (empty if none)."""
    d = Path(error_dir)
    if not d.is_dir():
        return []
    reports = sorted(d.glob(f"{ERROR_FILE_PREFIX}*.txt"))
    return [p.read_text().splitlines()[0] + f"  (full traceback: {p})" for p in reports]
