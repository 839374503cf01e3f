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
from rlgrasp.config import ConfigError
from rlgrasp.envs.factory import env_factory
from rlgrasp.evaluation.source import ENV_ERRORS
from rlgrasp.overrides import CommandLineError, check, unwritable
from rlgrasp.rundir import name_problem
from rlgrasp.sweep.objective import schedule_overrides, trial_overrides
from rlgrasp.sweep.score import KINDS
from rlgrasp.sweep.space import Space, to_overrides
from rlgrasp.sweep.study import PRUNERS, SAMPLERS, open_study, study_dir
from rlgrasp.train.validate import validate_train
from rlgrasp.utils import flatten

#: What training reports to ``on_eval`` (``rlgrasp.train.evaluation.evaluate.Evaluator.run``): the metrics a
#: sweep can optimize.
METRICS = ("success_rate", "mean_reward")
DIRECTIONS = ("maximize", "minimize")
LR_SCHEDULES = ("trial", "experiment")


class SweepError(ValueError):
    """A bad sweep input; the message is one line naming the key, its value and what is allowed."""


def _objective_checks(cfg: Any) -> list[tuple[str, Any, bool, str]]:
    """``objective`` and the keys it constrains (``rlgrasp.sweep.score``)."""
    o, reach = cfg.objective, cfg.objective.kind == "first_reach"
    return [
        ("objective.kind", o.kind, o.kind in KINDS, f"must be one of {', '.join(KINDS)}"),
        ("objective.threshold", o.threshold, 0 < o.threshold <= 1, "must be in (0, 1] (a success rate)"),
        (
            "objective.tie_break",
            o.tie_break,
            0 <= o.tie_break < 1,
            "must be in [0, 1) (a fraction of the frames; 0: no tie-break)",
        ),
        (
            "metric",
            cfg.metric,
            not reach or cfg.metric == "success_rate",
            "objective.kind=first_reach compares the success rate to its threshold: must be success_rate",
        ),
        (
            "direction",
            cfg.direction,
            not reach or cfg.direction in (None, "minimize"),
            "objective.kind=first_reach counts frames (fewer is better): must be minimize or null",
        ),
    ]


def check_values(cfg: Any) -> None:
    """The sweep's own keys: ``SweepError`` naming the first bad one."""
    seeds = list(cfg.trial.seeds)
    checks = [
        ("n_trials", cfg.n_trials, cfg.n_trials >= 1, "must be >= 1"),
        ("metric", cfg.metric, cfg.metric in METRICS, f"must be one of {', '.join(METRICS)}"),
        (
            "direction",
            cfg.direction,
            cfg.direction is None or cfg.direction in DIRECTIONS,
            f"must be one of {', '.join(DIRECTIONS)} or null (the objective's)",
        ),
        *_objective_checks(cfg),
        ("trial.seeds", seeds, len(set(seeds)) == len(seeds), "must not repeat a seed"),
        (
            "trial.lr_schedule",
            cfg.trial.lr_schedule,
            cfg.trial.lr_schedule in LR_SCHEDULES,
            f"must be one of {', '.join(LR_SCHEDULES)}",
        ),
        (
            "sampler.name",
            cfg.sampler.name,
            cfg.sampler.name in SAMPLERS,
            f"must be one of {', '.join(SAMPLERS)}",
        ),
        ("pruner.name", cfg.pruner.name, cfg.pruner.name in PRUNERS, f"must be one of {', '.join(PRUNERS)}"),
        ("worker", cfg.worker, cfg.worker >= 0, "must be >= 0"),
        (
            "timeout_min",
            cfg.timeout_min,
            cfg.timeout_min is None or cfg.timeout_min > 0,
            "must be > 0 or null",
        ),
    ]
    for key, value, ok, allowed in checks:
        if not ok:
            raise SweepError(f"sweep.{key}={value}: {allowed}")
    _check_study_name(cfg)
    problem = unwritable(study_dir(cfg), folder=True)
    if problem:
        raise SweepError(f"sweep.root_dir={cfg.root_dir}: cannot create {study_dir(cfg)}: {problem}")
    problem = storage_problem(cfg.storage)
    if problem:
        raise SweepError(problem)


def _check_study_name(cfg: Any) -> None:
    """The study's folder is ``<root_dir>/<study_name>``: a name with a path in it would put the
    journal, the trials' runs and the summary outside ``root_dir``."""
    problem = name_problem("sweep.study_name", cfg.study_name)
    if problem:
        raise SweepError(problem)


def storage_problem(storage: str | None) -> str | None:
    """Why ``sweep.storage`` cannot be opened (``None``: it can, or it is a server this does not ask):
    a journal file, or a ``sqlite:///`` database, must be creatable where it is named. Checked before
    the trials' configs are composed, not as Optuna's traceback when the study opens."""
    if not storage:
        return None  # the journal in the study directory, checked above
    if "://" not in storage:
        path = Path(storage)
    elif storage.startswith("sqlite:///"):
        path = Path(storage[len("sqlite:///") :])
        if not str(path) or str(path) == ":memory:":
            return None
    else:
        return None
    if path.is_dir():
        return f"sweep.storage={storage}: {path} is a directory (a journal or database file goes there)"
    if storage.startswith("sqlite:///") and not path.parent.is_dir():  # SQLite creates no folder
        return f"sweep.storage={storage}: cannot open {path}: {path.parent} is not a directory"
    problem = unwritable(path)
    return f"sweep.storage={storage}: cannot open {path}: {problem}" if problem else None


def _sample(d: BaseDistribution) -> Any:
    """One value of ``d`` that every trial could draw (its lower end, or its first choice)."""
    return d.choices[0] if isinstance(d, CategoricalDistribution) else d.low


def check_training(
    cfg: Any,
    train_overrides: Sequence[str],
    space: Space,
    enqueue: Sequence[Mapping[str, Any]],
    config_dir: str | Path,
) -> None:
    """The training config of a trial composes and is valid (``rlgrasp.train.validate``), and so
    do those with a value of every parameter (every choice of a named one) and with each enqueued
    set (a key naming no training key fails here). ``CommandLineError`` (the command line) or
    ``SweepError`` (a sweep value)."""
    run_dir = Path("/nonexistent/trial")  # composed, never created
    check("train", trial_overrides(cfg, train_overrides, [], run_dir), config_dir)
    seed = [f"seed={s}" for s in cfg.trial.seeds[:1]]
    fixed = [*schedule_overrides(cfg, train_overrides, config_dir), *seed]
    base = trial_overrides(cfg, train_overrides, [], run_dir, fixed)
    try:
        check("train", base, config_dir)
    except CommandLineError as exc:  # e.g. lr_schedule=experiment with an algo that has no such key
        raise SweepError(f"sweep.trial (lr_schedule={cfg.trial.lr_schedule}, seeds): {exc}") from None
    train_cfg = compose_train(base, config_dir)
    try:
        validate_train(train_cfg)
    except ConfigError as exc:
        raise SweepError(f"a trial's training config: {exc}") from None
    try:  # the env's own keywords (objects, randomization, ...): what training checks next
        env_factory(train_cfg.env)().close()
    except ENV_ERRORS as exc:
        raise SweepError(f"a trial's env: {exc}") from None
    sampled = {key: _sample(d) for key, d in space.dists.items()}
    variants = [sampled, *({**sampled, name: c} for name, sets in space.sets.items() for c in list(sets)[1:])]
    for params in variants:
        try:
            check("train", [*base, *space.overrides(params)], config_dir)
        except CommandLineError as exc:
            raise SweepError(f"sweep.params: {exc}") from None
    for i, item in enumerate(enqueue):
        flat = flatten(item)
        params = {k: v for k, v in flat.items() if k in space}
        others = {k: v for k, v in flat.items() if k not in space}
        try:
            check("train", [*base, *space.overrides(params), *to_overrides(others)], config_dir)
        except ValueError as exc:  # CommandLineError, or a named choice's unknown value
            raise SweepError(f"sweep.enqueue[{i}]: {exc}") from None


def load_existing(cfg: Any) -> optuna.Study:
    """The stored study, for a summary; ``SweepError`` when there is none (and nothing created)."""
    _check_study_name(cfg)
    where = cfg.storage if cfg.storage and "://" in cfg.storage else None
    if where is None:
        path = Path(cfg.storage) if cfg.storage else study_dir(cfg) / "journal.log"
        if not path.is_file():
            raise SweepError(
                f"no study to summarize: {path} does not exist (sweep={cfg.study_name}, "
                f"sweep.root_dir={cfg.root_dir})"
            )
        where = str(path)
    try:
        return open_study(cfg, create=False)
    except KeyError:
        raise SweepError(f"no study named {cfg.study_name!r} in {where}") from None
