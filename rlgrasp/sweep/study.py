"""The Optuna study: storage, sampler and pruner from config; resume bookkeeping.

Several ``rlgrasp-sweep`` processes on one study share its storage (a journal file by default, or
an RDB URL) and each asks Optuna for the next trial, so they cooperate without a coordinator.
"""

from __future__ import annotations

import inspect
import logging
import os
import socket
from collections.abc import Container, Mapping
from pathlib import Path
from typing import Any

import optuna
from optuna.storages import BaseStorage, JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import FrozenTrial, TrialState

from rlgrasp.sweep.space import encode_choice, override_value
from rlgrasp.utils import flatten

#: User attributes the objective writes on every trial.
ATTR_HOST, ATTR_PID, ATTR_INTERRUPTED, ATTR_RETRY_OF = "host", "pid", "interrupted", "retry_of"
ATTR_OVERRIDES = "extra_overrides"
ATTR_RUNS = "runs"  # one record per seed: seed, value, frames, metric, first_reach: reached_at
ATTR_OBJECTIVE = "objective"  # a study attribute: what a trial's value is, in words (the summary's)
log = logging.getLogger("rlgrasp.sweep")

SAMPLERS = {
    "tpe": lambda seed, kw: optuna.samplers.TPESampler(seed=seed, **kw),
    "random": lambda seed, kw: optuna.samplers.RandomSampler(seed=seed, **kw),
    "cmaes": lambda seed, kw: optuna.samplers.CmaEsSampler(seed=seed, **kw),
    "qmc": lambda seed, kw: optuna.samplers.QMCSampler(seed=seed, **kw),
    "gp": lambda seed, kw: optuna.samplers.GPSampler(seed=seed, **kw),
}
PRUNERS = {
    "median": optuna.pruners.MedianPruner,
    "percentile": optuna.pruners.PercentilePruner,
    "hyperband": optuna.pruners.HyperbandPruner,
    "successive_halving": optuna.pruners.SuccessiveHalvingPruner,
    "threshold": optuna.pruners.ThresholdPruner,
    "none": optuna.pruners.NopPruner,
}


def study_dir(cfg: Any) -> Path:
    """Where the study's journal, trial runs and summary live: ``<root_dir>/<study_name>``."""
    return Path(cfg.root_dir) / cfg.study_name


def study_direction(cfg: Any) -> str:
    """``sweep.direction``, or the objective's: first_reach counts frames (minimize); final scores a
    success rate or a reward (maximize)."""
    return cfg.direction or ("minimize" if cfg.objective.kind == "first_reach" else "maximize")


def make_storage(cfg: Any) -> BaseStorage | str:
    """Journal file (default ``<study dir>/journal.log``), or an RDB URL passed through to Optuna."""
    if cfg.storage and "://" in cfg.storage:
        return cfg.storage
    path = Path(cfg.storage) if cfg.storage else study_dir(cfg) / "journal.log"
    path.parent.mkdir(parents=True, exist_ok=True)
    return JournalStorage(JournalFileBackend(str(path)))


def make_sampler(cfg: Any) -> optuna.samplers.BaseSampler:
    name = cfg.sampler.name
    if name not in SAMPLERS:
        raise ValueError(f"sweep.sampler.name must be one of {sorted(SAMPLERS)}, got {name!r}")
    seed = None if cfg.sampler.seed is None else int(cfg.sampler.seed) + int(cfg.worker)
    return SAMPLERS[name](seed, dict(cfg.sampler.kwargs))


def make_pruner(cfg: Any) -> optuna.pruners.BasePruner:
    name = cfg.pruner.name
    if name not in PRUNERS:
        raise ValueError(f"sweep.pruner.name must be one of {sorted(PRUNERS)}, got {name!r}")
    cls, kwargs = PRUNERS[name], dict(cfg.pruner.kwargs)
    accepted = inspect.signature(cls).parameters
    dropped = sorted(k for k in kwargs if k not in accepted)
    if dropped:  # e.g. sweep.pruner.name=threshold on a config written for the median pruner
        log.warning("sweep.pruner.kwargs %s do not apply to the %s pruner: ignored", dropped, name)
    return cls(**{k: v for k, v in kwargs.items() if k in accepted})


def open_study(cfg: Any, create: bool = True) -> optuna.Study:
    """Create the study or load it (resume, or join processes already working on it)."""
    storage = make_storage(cfg)
    if not create:
        return optuna.load_study(study_name=cfg.study_name, storage=storage)
    return optuna.create_study(
        study_name=cfg.study_name,
        storage=storage,
        sampler=make_sampler(cfg),
        pruner=make_pruner(cfg),
        direction=study_direction(cfg),
        load_if_exists=True,
    )


def counts_toward_budget(t: FrozenTrial) -> bool:
    """Finished trials count toward ``n_trials``; an interrupted one does not (it is retried)."""
    if t.state in (TrialState.COMPLETE, TrialState.PRUNED):
        return True
    return t.state == TrialState.FAIL and not t.user_attrs.get(ATTR_INTERRUPTED, False)


def n_finished(study: optuna.Study) -> int:
    return sum(counts_toward_budget(t) for t in study.get_trials(deepcopy=False))


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def fail_dead_trials(study: optuna.Study) -> list[int]:
    """Mark RUNNING trials whose process on this host is gone (kill -9, crash) as interrupted.

    Trials of live processes, or of other hosts, are left alone: they may still be running.
    """
    host, dead = socket.gethostname(), []
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        pid = t.user_attrs.get(ATTR_PID)
        if t.user_attrs.get(ATTR_HOST) == host and pid is not None and not _pid_alive(int(pid)):
            study._storage.set_trial_user_attr(t._trial_id, ATTR_INTERRUPTED, True)
            study._storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
            dead.append(t.number)
    return dead


def requeue_interrupted(study: optuna.Study) -> list[int]:
    """Enqueue the parameters of each interrupted trial once more (a resumed sweep retries them)."""
    trials = study.get_trials(deepcopy=False)
    retried = {t.user_attrs.get(ATTR_RETRY_OF) for t in trials}
    out = []
    for t in trials:
        if t.state == TrialState.FAIL and t.user_attrs.get(ATTR_INTERRUPTED) and t.number not in retried:
            attrs = {ATTR_RETRY_OF: t.number}
            if t.user_attrs.get(ATTR_OVERRIDES):
                attrs[ATTR_OVERRIDES] = t.user_attrs[ATTR_OVERRIDES]
            study.enqueue_trial(t.params, user_attrs=attrs, skip_if_exists=False)
            out.append(t.number)
    return out


def enqueue_initial(study: optuna.Study, items: list[Mapping[str, Any]], space: Container[str]) -> int:
    """Enqueue ``sweep.enqueue`` on a new study; keys outside the space become fixed overrides."""
    if study.get_trials(deepcopy=False):
        return 0
    for item in items:
        flat = flatten(item)
        params = {k: encode_choice(v) for k, v in flat.items() if k in space}
        extra = [f"{k}={override_value(v)}" for k, v in flat.items() if k not in space]
        study.enqueue_trial(params, user_attrs={ATTR_OVERRIDES: extra} if extra else None)
    return len(items)
