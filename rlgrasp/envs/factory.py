"""The one way to build envs from a config: the ``env`` node's ``_target_`` with its fields as keywords."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from rlgrasp.envs import gym_env

#: What builds one env per call (``env_factory``'s result; collectors, evaluation and specs take it).
EnvFactory = Callable[[], Any]


def env_factory(env_cfg: DictConfig | Mapping[str, Any]) -> EnvFactory:
    """A picklable partial that builds one env per call.

    Used by the collector workers, training's evaluation, ``rlgrasp-eval``, export and the
    benchmarks. Being a partial, it travels to spawned workers and Ray actors as it is;
    ``_convert_`` makes the keywords (``randomization`` as a preset name or a mapping) plain Python
    values. ``_recursive_=False``: the env builds its parts (``env.task``) itself, on its own scene.
    """
    return instantiate(env_cfg, _partial_=True, _convert_="all", _recursive_=False)


def episode_steps(env_cfg: DictConfig, default: int = 50) -> int:
    """The steps of one episode of the env ``env_cfg`` builds, for the periodic evaluation's rollouts and
    the staggered starts: rlgrasp's env's ``sim.max_episode_steps``; another package's (``env=gym``) its
    ``max_episode_steps``, or, null there, its registration's (``default`` where it has none)."""
    steps = OmegaConf.select(env_cfg, "sim.max_episode_steps")
    if steps is None and env_cfg.get("_target_") == gym_env.TARGET:
        steps = env_cfg.get("max_episode_steps") or gym_env.registered_steps(env_cfg.id)
    return int(steps) if steps is not None else default
