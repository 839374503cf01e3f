"""Run a sweep: check everything, then run (or resume, or join) the study and summarize it."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import optuna
from hydra.errors import HydraException
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from rlgrasp.compose import compose_sweep
from rlgrasp.config import CONFIG_DIR
from rlgrasp.overrides import CommandLineError, explain
from rlgrasp.sweep.checks import SweepError, check_training, check_values, load_existing
from rlgrasp.sweep.objective import Interrupted, Objective, catch_signals, stop_requested
from rlgrasp.sweep.score import describe
from rlgrasp.sweep.space import parse_space
from rlgrasp.sweep.study import (
    ATTR_OBJECTIVE,
    enqueue_initial,
    fail_dead_trials,
    n_finished,
    open_study,
    requeue_interrupted,
    study_dir,
)
from rlgrasp.sweep.summary import write_summary

log = logging.getLogger("rlgrasp.sweep")


def compose(sweep_overrides: list[str], config_dir: str | Path) -> Any:
    """The sweep config; a command line Hydra refuses is a one-line ``CommandLineError``."""
    try:
        return compose_sweep(sweep_overrides, config_dir)
    except (HydraException, OmegaConfBaseException) as exc:
        raise CommandLineError(explain(exc, sweep_overrides)) from None


def run_sweep(
    sweep_overrides: list[str],
    train_overrides: list[str],
    config_dir: str | Path = CONFIG_DIR,
    summary_only: bool = False,
) -> dict:
    """Check everything, then run (or resume, or join) the study until it holds ``n_trials`` finished
    trials; summarize. Bad input: ``CommandLineError`` or ``SweepError``, nothing written."""
    cfg = compose(sweep_overrides, config_dir)
    out_dir = study_dir(cfg)
    if summary_only or cfg.summary_only:
        return write_summary(load_existing(cfg), out_dir, config_dir, cfg.plots)

    check_values(cfg)
    try:
        space = parse_space(OmegaConf.to_container(cfg.params, resolve=True))
    except ValueError as exc:
        raise SweepError(str(exc)) from None
    enqueue = OmegaConf.to_container(cfg.enqueue, resolve=True)
    check_training(cfg, train_overrides, space, enqueue, config_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "sweep.yaml").write_text(OmegaConf.to_yaml(cfg))
    study = open_study(cfg)
    study.set_user_attr(ATTR_OBJECTIVE, describe(cfg))
    enqueue_initial(study, enqueue, space)
    dead = fail_dead_trials(study)
    retried = requeue_interrupted(study)
    log.info(
        "study %s in %s: %d/%d trials finished%s%s",
        cfg.study_name,
        out_dir,
        n_finished(study),
        cfg.n_trials,
        f"; trials {dead} of dead processes marked interrupted" if dead else "",
        f"; retrying interrupted trials {retried}" if retried else "",
    )
    interrupted = _optimize(study, Objective(cfg, config_dir, train_overrides, space), cfg)
    study = optuna.load_study(study_name=cfg.study_name, storage=study._storage)
    result = write_summary(study, out_dir, config_dir, cfg.plots)
    result["interrupted"] = interrupted
    result["finished"] = n_finished(study)
    return result


def _optimize(study, objective, cfg) -> bool:
    """One trial at a time until ``n_trials`` are finished or ``timeout_min`` is spent; returns True
    if a signal stopped the sweep."""
    deadline = time.monotonic() + cfg.timeout_min * 60 if cfg.timeout_min else float("inf")
    with catch_signals():
        try:
            while n_finished(study) < cfg.n_trials and time.monotonic() < deadline:
                study.optimize(objective, n_trials=1, catch=(Exception,), gc_after_trial=True)
                if stop_requested():
                    raise KeyboardInterrupt
        except Interrupted as exc:
            log.warning("%s: the sweep stops; run the same command again to resume", exc)
            return True
        except KeyboardInterrupt:
            log.warning("interrupted between trials; run the same command again to resume")
            return True
    return False
