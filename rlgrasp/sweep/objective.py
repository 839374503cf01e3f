"""One trial = one training run: compose its config with Hydra, train, report evals to the pruner."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import signal
import socket
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import optuna
from omegaconf import DictConfig

from rlgrasp.compose import compose_train
from rlgrasp.sweep.space import suggest, to_overrides
from rlgrasp.sweep.study import ATTR_HOST, ATTR_INTERRUPTED, ATTR_OVERRIDES, ATTR_PID, study_dir
from rlgrasp.train.loop import train

log = logging.getLogger("rlgrasp.sweep")


class Interrupted(KeyboardInterrupt):
    """SIGINT/SIGTERM arrived during a trial (training saved a checkpoint and returned)."""


def trial_overrides(
    cfg: Any, train_overrides: list[str], params: Mapping[str, Any], run_dir: Path
) -> list[str]:
    """Command-line overrides, then the sweep's fixed ones, the trial budget, the sampled values."""
    return [
        *train_overrides,
        *cfg.overrides,
        f"total_frames={cfg.trial.total_frames}",
        f"time_budget_min={'null' if cfg.trial.time_budget_min is None else cfg.trial.time_budget_min}",
        *to_overrides(params),
        f"paths.output_dir={run_dir}",
    ]


class Objective:
    """Callable for ``study.optimize``: returns the final eval ``metric`` of the trial's run.

    Each eval is reported at step = frames; the pruner may then stop the run (``TrialPruned``
    propagates out of ``train``, which saves a checkpoint first). A crash is an ordinary exception,
    which Optuna records as a failed trial. A Ctrl-C or SIGTERM makes training save and return; the
    trial is then marked interrupted and failed, and a resumed sweep runs its parameters again.
    """

    def __init__(self, cfg: Any, config_dir: str | Path, train_overrides: list[str], space: Mapping) -> None:
        self.cfg = cfg
        self.config_dir = Path(config_dir)
        self.train_overrides = list(train_overrides)
        self.space = space

    def compose(self, trial: optuna.Trial) -> DictConfig:
        params = suggest(trial, self.space)
        run_dir = (study_dir(self.cfg) / "trials" / f"{trial.number:04d}").resolve()
        extra = list(trial.user_attrs.get(ATTR_OVERRIDES, []))
        overrides = trial_overrides(self.cfg, self.train_overrides, params, run_dir) + extra
        trial.set_user_attr("run_dir", str(run_dir))
        trial.set_user_attr("overrides", overrides)
        return compose_train(overrides, self.config_dir)

    def __call__(self, trial: optuna.Trial) -> float:
        trial.set_user_attr(ATTR_HOST, socket.gethostname())
        trial.set_user_attr(ATTR_PID, os.getpid())
        train_cfg = self.compose(trial)
        report = _Report(trial, self.cfg.metric, train_cfg.total_frames)
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
            trial.set_user_attr(ATTR_INTERRUPTED, True)
            raise Interrupted(f"signal {_caught[0] if _caught else 'SIGINT'} during trial {trial.number}")
        value = float(report.last.get(self.cfg.metric, math.nan))
        if math.isnan(value):
            raise RuntimeError(f"trial {trial.number}: no final value of {self.cfg.metric!r}")
        trial.set_user_attr("final_eval", {k: float(v) for k, v in report.last.items()})
        log.info("trial %d: %s=%.4f", trial.number, self.cfg.metric, value)
        return value


class _Report:
    """Training's ``on_eval``: report ``metric`` at step = frames; raise ``TrialPruned`` when the
    pruner says so (not at the final evaluation)."""

    def __init__(self, trial: optuna.Trial, metric: str, total_frames: int) -> None:
        self.trial, self.metric, self.total_frames = trial, metric, total_frames
        self.last: dict[str, float] = {}

    def __call__(self, frames: int, metrics: dict[str, float]) -> None:
        if self.metric not in metrics:
            raise KeyError(f"sweep.metric={self.metric!r} is not an eval metric; have {sorted(metrics)}")
        self.last = dict(metrics)
        self.trial.report(float(metrics[self.metric]), step=int(frames))
        if frames < self.total_frames and self.trial.should_prune():
            raise optuna.TrialPruned(f"{self.metric}={metrics[self.metric]:.3f} at {frames:,} frames")


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
