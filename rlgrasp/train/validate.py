"""Refusing a bad training config before any worker starts: each key checked against what is
allowed, the first problem (and how many more) in one ``ConfigError`` line.

The schemas (``rlgrasp.config``) say what type each key has; these checks say what values make a
run: the run's own keys, the collector's, the model's, the evaluation's and the checkpoints', each
algorithm's from its package (``Algorithm.check`` through the registry), the device, and another
package's env (``env=gym``: built once to check it). It sits with the training core, above the
parts it reads, so the schemas below need none of them.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator
from typing import Any

import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf

from rlgrasp.algos.common import positive
from rlgrasp.algos.registry import entry, unknown_name
from rlgrasp.envs import gym_env
from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.envs.randomization import Randomizer
from rlgrasp.errors import ConfigError
from rlgrasp.legacy import moved_target
from rlgrasp.locate import NotImportable, locate
from rlgrasp.models.cnn import POOLINGS
from rlgrasp.utils import plain


def _train_problems(cfg: Any, batch: int) -> list[str]:
    """Each bad value of a composed training config as ``key=value: what is allowed``; ``batch``: the
    collector's frames per batch."""
    checks = [
        *_run_checks(cfg),
        *_collector_checks(cfg.collector),
        *_algo_checks(cfg, batch, cfg.env.get("camera")),
        *_model_checks(cfg.model),
        *_model_camera_checks(cfg.model, cfg.env.get("camera")),
        *_eval_checkpoint_checks(cfg.eval, cfg.checkpoint),
    ]
    return (
        [f"{key}={value!r}: {allowed}" for key, value, ok, allowed in checks if not ok]
        + _device_problems(cfg.device)
        + _eval_randomization_problems(cfg.eval.get("randomization"))
    )


def _run_checks(cfg: Any) -> list[tuple[str, Any, bool, str]]:
    """The run's own keys: its seed, its name (a folder) and its budgets."""
    return [
        ("seed", cfg.seed, 0 <= cfg.seed < 2**32, "must be an integer in [0, 2**32)"),
        (
            "experiment_name",
            cfg.experiment_name,
            _one_path_component(cfg.experiment_name),
            "must be a plain name (no '/', not '..' or empty): it names a folder under the outputs",
        ),
        ("total_frames", cfg.total_frames, cfg.total_frames > 0, "must be > 0"),
        (
            "time_budget_min",
            cfg.time_budget_min,
            cfg.time_budget_min is None or cfg.time_budget_min > 0,
            "must be > 0 or null",
        ),
    ]


def _collector_checks(c: Any) -> list[tuple[str, Any, bool, str]]:
    return [
        ("collector.num_workers", c.num_workers, c.num_workers >= 0, "must be >= 0 (0: in-process)"),
        ("collector.envs_per_worker", c.envs_per_worker, c.envs_per_worker >= 1, "must be >= 1"),
        ("collector.steps_per_env", c.steps_per_env, c.steps_per_env >= 1, "must be >= 1"),
        ("collector.torch_threads", c.torch_threads, c.torch_threads >= 1, "must be >= 1"),
        (
            "collector.worker_timeout_s",
            c.worker_timeout_s,
            positive(c.worker_timeout_s),
            "must be > 0 (seconds a batch may take)",
        ),
    ]


def _model_checks(m: Any) -> list[tuple[str, Any, bool, str]]:
    """The MLP's keys (a camera model's own are ``_model_camera_checks``')."""
    distribution = m.get("distribution", "tanh_normal")  # a camera model has no such key
    return [
        (
            "model.hidden_sizes",
            list(m.hidden_sizes),
            len(m.hidden_sizes) > 0 and all(positive(h) for h in m.hidden_sizes),
            "must be a non-empty list of positive sizes",
        ),
        (
            "model.activation",
            m.activation,
            m.activation in ("tanh", "relu", "elu"),
            "must be tanh, relu or elu",
        ),
        (
            "model.distribution",
            distribution,
            distribution in ("tanh_normal", "normal"),
            "must be tanh_normal or normal",
        ),
        ("model.obs_clip", m.obs_clip, m.obs_clip > 0, "must be > 0 (the normalized observation's bound)"),
    ]


def _eval_checkpoint_checks(e: Any, k: Any) -> list[tuple[str, Any, bool, str]]:
    return [
        ("eval.episodes", e.episodes, e.episodes >= 1, "must be >= 1"),
        (
            "eval.final_episodes",
            e.final_episodes,
            e.final_episodes is None or e.final_episodes >= 1,
            "must be >= 1 or null",
        ),
        ("eval.num_envs", e.num_envs, e.num_envs >= 1, "must be >= 1"),
        ("checkpoint.keep_last", k.keep_last, k.keep_last >= 1, "must be >= 1"),
        (
            "checkpoint.interval_frames",
            k.interval_frames,
            k.interval_frames >= 0,
            "must be >= 0 (0: only at the end)",
        ),
    ]


def _eval_randomization_problems(spec: Any) -> list[str]:
    """A bad ``eval.randomization`` now, not at the first evaluation minutes into the run."""
    if spec is None:
        return []
    try:
        Randomizer(plain(spec))
    except (ValueError, OSError) as exc:
        return [f"eval.randomization={plain(spec)!r}: {exc}"]
    return []


def _one_path_component(name: Any) -> bool:
    """A name that stays one folder below where it is joined (no separator, no '..', not absolute)."""
    text = str(name)
    return bool(text) and text not in (".", "..") and "/" not in text and "\\" not in text


def _model_camera_checks(m: Any, camera: Any) -> list[tuple[str, Any, bool, str]]:
    """A camera env needs a camera policy (model=cnn); what a camera-less one needs is the algorithm's
    to say (PPO: a state model; DAgger refuses the env itself, naming its student)."""
    if not camera:
        return []
    return [
        ("model", m.name, m.name == "cnn", "must be cnn with a camera (or cameras=none for mlp)"),
        *(_cnn_checks(m) if m.name == "cnn" else []),
    ]


def _cnn_checks(m: Any) -> list[tuple[str, Any, bool, str]]:
    layers = f"needs one entry per layer of model.channels={list(m.channels)}"
    return [
        ("model.pooling", m.pooling, m.pooling in POOLINGS, f"must be one of {', '.join(POOLINGS)}"),
        ("model.kernel_sizes", list(m.kernel_sizes), len(m.kernel_sizes) == len(m.channels), layers),
        ("model.strides", list(m.strides), len(m.strides) == len(m.channels), layers),
    ]


def _algo_checks(cfg: Any, batch: int, camera: Any) -> list[tuple[str, Any, bool, str]]:
    """The checks of ``algo``'s own keys, each algorithm's from its package (an unknown name is refused,
    naming the registered ones)."""
    found = entry(cfg.algo.name)
    return found.check(cfg, batch, camera) if found is not None else [unknown_name(cfg.algo.name)]


def _device_problems(device: str) -> list[str]:
    if device in ("auto", "cpu"):
        return []
    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError):
        return [f"device={device!r}: must be auto, cpu, cuda or cuda:<n>"]
    if dev.type == "cuda" and not torch.cuda.is_available():
        return [f"device={device!r}: CUDA is not available on this machine (use device=cpu or auto)"]
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        return [f"device={device!r}: this machine has {torch.cuda.device_count()} CUDA device(s)"]
    if dev.type not in ("cpu", "cuda"):
        return [f"device={device!r}: must be auto, cpu, cuda or cuda:<n>"]
    return []


def _built(key: str, node: Any, build: Callable[[Any], Any]) -> Any:
    """``build(node)`` for a ``_target_`` node; ``ConfigError`` naming the target when it fails."""
    try:
        return build(node)
    except Exception as exc:  # noqa: BLE001 - Hydra wraps whatever the target raised
        reason = " ".join(str(exc).split(", set env var HYDRA_FULL_ERROR")[0].split())[:300]
        raise ConfigError(f"{key}._target_={node.get('_target_')!r} cannot be built: {reason}") from None


def _warn_about_workers(workers: int) -> None:
    """Far more worker processes than cores is allowed (a shared machine may lend more later) but
    slows every one of them: say so."""
    cores = os.cpu_count() or 1
    if workers > 2 * cores:
        logging.getLogger("rlgrasp.train").warning(
            "collector.num_workers=%d on a machine with %d cores: each worker gets a fraction of a core "
            "(collector.num_workers=%d or fewer is usually fastest)",
            workers,
            cores,
            cores,
        )


def _targets(node: Any, prefix: str = "") -> Iterator[tuple[str, str]]:
    """Each ``(key, dotted path)`` of a ``_target_`` in a plain config, its interpolations left out."""
    if isinstance(node, dict):
        for key, value in node.items():
            where = f"{prefix}.{key}" if prefix else str(key)
            if key == "_target_" and isinstance(value, str) and not value.startswith("${"):
                yield where, value
            else:
                yield from _targets(value, where)
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _targets(value, f"{prefix}[{i}]")


def _importable(target: str) -> str | None:
    """None where ``module.name`` can be had, else why not, in a few words."""
    try:
        locate(target)
    except NotImportable as exc:
        return str(exc)
    return None


def _target_problems(cfg: Any) -> list[str]:
    """Each ``_target_`` the user's config names (it is the user's own: importing it is what the run
    would do next) that cannot be imported, as one line; a module that moved says where it is now."""
    problems = []
    for key, target in _targets(OmegaConf.to_container(cfg, resolve=False)):
        why = _importable(target)
        if why is None:
            continue
        today = moved_target(target)
        hint = f"; it moved: write {today!r}" if today != target else ""
        problems.append(f"{key}={target!r} cannot be imported ({why}){hint}")
    return problems


def validate_train(cfg: Any) -> None:
    """Refuse a training config with a bad value: ``ConfigError`` naming the first (and how many
    more). The env's own keywords are checked by the env when the learner builds it, before workers."""
    if OmegaConf.is_config(cfg) and (targets := _target_problems(cfg)):
        raise ConfigError(targets[0])
    if OmegaConf.is_config(cfg) and cfg.env.get("_target_") == EnvConfig._target_:
        try:
            OmegaConf.merge(OmegaConf.structured(EnvConfig), cfg.env)
        except Exception as exc:  # noqa: BLE001 - OmegaConf's validation errors
            raise ConfigError(f"env: {str(exc).splitlines()[0]}") from None
    collector = _built("collector", cfg.collector, lambda node: instantiate(node, _convert_="all"))
    _built("logger", cfg.logger, lambda node: instantiate(node, _partial_=True))  # built with the run dir
    _warn_about_workers(cfg.collector.num_workers)
    problems = _train_problems(cfg, collector.frames_per_batch)
    if problems:
        more = f" (and {len(problems) - 1} more: {'; '.join(problems[1:])})" if len(problems) > 1 else ""
        raise ConfigError(problems[0] + more)
    if cfg.env.get("_target_") == gym_env.TARGET:  # another package's env: built once to check it
        her = bool(OmegaConf.select(cfg, "algo.her.enabled", default=False))
        gym_env.check_config(plain(cfg.env), her=her)
