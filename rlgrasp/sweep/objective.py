"""One trial = one training run per seed: compose its config with Hydra, train, score its evaluations
(``rlgrasp.sweep.score``) and report them to the pruner."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import signal
import socket
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import optuna
from omegaconf import DictConfig

from rlgrasp.compose import compose_train
from rlgrasp.sweep.score import RunScore
from rlgrasp.sweep.space import Space, suggest
from rlgrasp.sweep.study import ATTR_HOST, ATTR_INTERRUPTED, ATTR_OVERRIDES, ATTR_PID, ATTR_RUNS, study_dir
from rlgrasp.train.loop import train

log = logging.getLogger("rlgrasp.sweep")


class Interrupted(KeyboardInterrupt):
    """SIGINT/SIGTERM arrived during a trial (training saved a checkpoint and returned)."""


def trial_overrides(
    cfg: Any, train_overrides: Sequence[str], params: Sequence[str], run_dir: Path, fixed: Sequence[str] = ()
) -> list[str]:
    """Command-line overrides, then the sweep's fixed ones, the trial budget, ``fixed`` (the learning
    rate schedule's, a seed), the sampled values (as overrides)."""
    return [
        *train_overrides,
        *cfg.overrides,
        f"total_frames={cfg.trial.total_frames}",
        f"time_budget_min={'null' if cfg.trial.time_budget_min is None else cfg.trial.time_budget_min}",
        *fixed,
        *params,
        f"paths.output_dir={run_dir}",
    ]


def schedule_overrides(cfg: Any, train_overrides: Sequence[str], config_dir: str | Path) -> list[str]:
    """``trial.lr_schedule=experiment``: anneal over the experiment's frames, not the trial's (the
    trial is then the first part of the run it stands for, at that run's learning rates)."""
    if cfg.trial.lr_schedule != "experiment":
        return []
    experiment = compose_train([*train_overrides, *cfg.overrides], config_dir)
    frames = experiment.algo.schedule.anneal_lr_frames or experiment.total_frames
    return [f"algo.schedule.anneal_lr_frames={frames}"]


class Objective:
    """Callable for ``study.optimize``: trains the trial's parameters once per seed of
    ``trial.seeds`` (or once) and returns the mean of the runs' values (``sweep.objective``).

    The first run's evaluations are reported at step = frames; the pruner may then stop it
    (``TrialPruned`` propagates out of ``train``, which saves a checkpoint first), which ends the
    trial. Each run's value is kept in the trial's ``runs`` user attribute as it finishes. A crash
    is an ordinary exception, which Optuna records as a failed trial. A Ctrl-C or SIGTERM makes
    training save and return; the trial is then marked interrupted and failed, and a resumed sweep
    runs its parameters again (every seed).
    """

    def __init__(self, cfg: Any, config_dir: str | Path, train_overrides: list[str], space: Space) -> None:
        self.cfg = cfg
        self.config_dir = Path(config_dir)
        self.train_overrides = list(train_overrides)
        self.space = space
        self.schedule = schedule_overrides(cfg, self.train_overrides, self.config_dir)

    def compose(self, trial: optuna.Trial, params: dict[str, Any], seed: int | None) -> DictConfig:
        """The training config of one run: the trial's directory, or its ``seed_<n>`` folder."""
        trial_dir = (study_dir(self.cfg) / "trials" / f"{trial.number:04d}").resolve()
        run_dir = trial_dir if seed is None else trial_dir / f"seed_{seed}"
        extra = list(trial.user_attrs.get(ATTR_OVERRIDES, []))
        values = self.space.overrides(params)

        def overrides(fixed: list[str]) -> list[str]:
            return trial_overrides(self.cfg, self.train_overrides, values, run_dir, fixed) + extra

        if "overrides" not in trial.user_attrs:  # the first run's, without its seed: the best config's
            trial.set_user_attr("run_dir", str(trial_dir))
            trial.set_user_attr("overrides", overrides(self.schedule))
        seeded = [*self.schedule, *([] if seed is None else [f"seed={seed}"])]
        return compose_train(overrides(seeded), self.config_dir)

    def __call__(self, trial: optuna.Trial) -> float:
        try:
            return self._trial(trial)
        except Interrupted:
            raise
        except KeyboardInterrupt:  # between two runs or after the last: the trial is still interrupted
            raise _interrupted(trial) from None

    def _trial(self, trial: optuna.Trial) -> float:
        """The trial's runs, one per seed, and their mean value."""
        trial.set_user_attr(ATTR_HOST, socket.gethostname())
        trial.set_user_attr(ATTR_PID, os.getpid())
        params = suggest(trial, self.space)
        seeds: list[int | None] = list(self.cfg.trial.seeds) or [None]
        runs: list[dict[str, Any]] = []
        for i, seed in enumerate(seeds):
            train_cfg = self.compose(trial, params, seed)
            score = RunScore(self.cfg.objective, self.cfg.metric, train_cfg.total_frames)
            self._train(trial, train_cfg, _Report(trial, score, prune=i == 0))
            if math.isnan(score.value()):
                raise RuntimeError(f"trial {trial.number}: no final value of {self.cfg.metric!r}")
            runs.append({"seed": train_cfg.seed, **score.record()})
            trial.set_user_attr(ATTR_RUNS, runs)
            log.info("trial %d, seed %d: value %.6g", trial.number, train_cfg.seed, runs[-1]["value"])
        value = sum(r["value"] for r in runs) / len(runs)
        log.info("trial %d: value %.6g (%s)", trial.number, value, self.cfg.objective.kind)
        return value

    def _train(self, trial: optuna.Trial, train_cfg: DictConfig, report: _Report) -> None:
        """One run; a signal marks the trial interrupted and raises ``Interrupted``."""
        interrupted = False
        try:
            with _closing_new_log_handlers():
                train(train_cfg, on_eval=report)
        except KeyboardInterrupt:  # arrived outside the loop that turns it into a clean stop
            interrupted = True
        except optuna.TrialPruned:
            raise
        except Exception as exc:
            trial.set_user_attr("error", f"{type(exc).__name__}: {exc}")
            raise
        if _caught or interrupted:
            raise _interrupted(trial)


def _interrupted(trial: optuna.Trial) -> Interrupted:
    """Mark the trial interrupted (a resumed sweep runs its parameters again); the exception to raise."""
    trial.set_user_attr(ATTR_INTERRUPTED, True)
    return Interrupted(f"signal {_caught[0] if _caught else 'SIGINT'} during trial {trial.number}")


class _Report:
    """Training's ``on_eval``: score each evaluation; with ``prune``, report the score at step =
    frames and raise ``TrialPruned`` when the pruner says so (not at the final evaluation). Optuna
    takes one report per step, so only a trial's first run reports."""

    def __init__(self, trial: optuna.Trial, score: RunScore, prune: bool) -> None:
        self.trial, self.score, self.prune = trial, score, prune

    def __call__(self, frames: int, metrics: dict[str, float]) -> None:
        value = self.score.add(frames, metrics)
        if not self.prune:
            return
        self.trial.report(value, step=int(frames))
        if frames < self.score.budget and self.trial.should_prune():
            raise optuna.TrialPruned(f"value {value:.6g} at {frames:,} frames")


@contextlib.contextmanager
def _closing_new_log_handlers() -> Iterator[None]:
    """Close the handlers training adds (the run's train.log), so the next trial does not write there."""
    logger = logging.getLogger("rlgrasp.train")
    before = list(logger.handlers)
    try:
        yield
    finally:
        for h in [h for h in logger.handlers if h not in before]:
            logger.removeHandler(h)
            h.close()


_caught: list[int] = []


def _handler(signum, frame):  # noqa: ARG001 - signal handler signature
    _caught.append(signum)
    raise KeyboardInterrupt  # training catches it, saves a checkpoint and returns


def stop_requested() -> bool:
    """A SIGINT/SIGTERM arrived (recorded even when the KeyboardInterrupt was swallowed somewhere)."""
    return bool(_caught)


@contextlib.contextmanager
def catch_signals() -> Iterator[None]:
    """SIGINT and SIGTERM (a cluster's preemption) both stop the sweep as Ctrl-C would, and are
    recorded, so that a signal landing between trials or in a callback is not lost."""
    _caught.clear()
    old = {sig: signal.signal(sig, _handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
