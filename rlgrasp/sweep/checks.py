"""Refuse a sweep that cannot run before anything is written: its own values, the training command
every trial composes (the fixed overrides and a sample of each parameter), the study directory, and
for a summary, the stored study. A bad value would otherwise surface in trial 0 (or in every trial,
each recorded as failed)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import optuna
from optuna.distributions import BaseDistribution, CategoricalDistribution

from rlgrasp.compose import compose_train
from rlgrasp.config import ConfigError, validate_train
from rlgrasp.envs.factory import env_factory
from rlgrasp.evaluation.source import ENV_ERRORS
from rlgrasp.overrides import CommandLineError, check, unwritable
from rlgrasp.sweep.objective import trial_overrides
from rlgrasp.sweep.space import to_overrides
from rlgrasp.sweep.study import PRUNERS, SAMPLERS, open_study, study_dir
from rlgrasp.utils import flatten

#: What training reports to ``on_eval`` (``rlgrasp.train.evaluate.Evaluator.run``): the metrics a
#: sweep can optimize.
METRICS = ("success_rate", "mean_reward")
DIRECTIONS = ("maximize", "minimize")


class SweepError(ValueError):
    """A bad sweep input; the message is one line naming the key, its value and what is allowed."""


def check_values(cfg: Any) -> None:
    """The sweep's own keys: ``SweepError`` naming the first bad one."""
    checks = [
        ("n_trials", cfg.n_trials, cfg.n_trials >= 1, "must be >= 1"),
        ("metric", cfg.metric, cfg.metric in METRICS, f"must be one of {', '.join(METRICS)}"),
        ("direction", cfg.direction, cfg.direction in DIRECTIONS, f"must be one of {', '.join(DIRECTIONS)}"),
        ("sampler.name", cfg.sampler.name, cfg.sampler.name in SAMPLERS,
         f"must be one of {', '.join(SAMPLERS)}"),
        ("pruner.name", cfg.pruner.name, cfg.pruner.name in PRUNERS, f"must be one of {', '.join(PRUNERS)}"),
        ("worker", cfg.worker, cfg.worker >= 0, "must be >= 0"),
        ("timeout_min", cfg.timeout_min, cfg.timeout_min is None or cfg.timeout_min > 0,
         "must be > 0 or null"),
    ]
    for key, value, ok, allowed in checks:
        if not ok:
            raise SweepError(f"sweep.{key}={value}: {allowed}")
    problem = unwritable(study_dir(cfg), folder=True)
    if problem:
        raise SweepError(f"sweep.root_dir={cfg.root_dir}: cannot create {study_dir(cfg)}: {problem}")


def _sample(d: BaseDistribution) -> Any:
    """One value of ``d`` that every trial could draw (its lower end, or its first choice)."""
    return d.choices[0] if isinstance(d, CategoricalDistribution) else d.low


def check_training(
    cfg: Any,
    train_overrides: Sequence[str],
    space: Mapping[str, BaseDistribution],
    enqueue: Sequence[Mapping[str, Any]],
    config_dir: str | Path,
) -> None:
    """The training config of a trial composes and is valid (``rlgrasp.config.validate_train``), and so
    do those with a value of every parameter and with each enqueued set (a key naming no training key
    fails here). ``CommandLineError`` (the command line) or ``SweepError`` (a sweep value)."""
    run_dir = Path("/nonexistent/trial")  # composed, never created
    base = trial_overrides(cfg, train_overrides, {}, run_dir)
    check("train", base, config_dir)
    train_cfg = compose_train(base, config_dir)
    try:
        validate_train(train_cfg)
    except ConfigError as exc:
        raise SweepError(f"a trial's training config: {exc}") from None
    try:  # the env's own keywords (objects, randomization, ...): what training checks next
        env_factory(train_cfg.env)().close()
    except ENV_ERRORS as exc:
        raise SweepError(f"a trial's env: {exc}") from None
    sampled = {key: _sample(d) for key, d in space.items()}
    try:
        check("train", [*base, *to_overrides(sampled)], config_dir)
    except CommandLineError as exc:
        raise SweepError(f"sweep.params: {exc}") from None
    for i, item in enumerate(enqueue):
        try:
            check("train", [*base, *to_overrides(flatten(item))], config_dir)
        except CommandLineError as exc:
            raise SweepError(f"sweep.enqueue[{i}]: {exc}") from None


def load_existing(cfg: Any) -> optuna.Study:
    """The stored study, for a summary; ``SweepError`` when there is none (and nothing created)."""
    where = cfg.storage if cfg.storage and "://" in cfg.storage else None
    if where is None:
        path = Path(cfg.storage) if cfg.storage else study_dir(cfg) / "journal.log"
        if not path.is_file():
            raise SweepError(f"no study to summarize: {path} does not exist (sweep={cfg.study_name}, "
                             f"sweep.root_dir={cfg.root_dir})")
        where = str(path)
    try:
        return open_study(cfg, create=False)
    except KeyError:
        raise SweepError(f"no study named {cfg.study_name!r} in {where}") from None
