"""A training run's life around its loop: the run directory's lock, the stop signals, the logger and
every callback closed however the run ends, and what each way of ending keeps and says.

The loop (``rlgrasp.train.loop.Trainer.fit``) reads straight down; ``Trainer.run`` runs it inside
``guarded``, and every way it can end other than by its budget is decided there, once for all
algorithms:

- a stop signal or Ctrl-C (``Stopped``, ``KeyboardInterrupt``): a checkpoint, and the run returns
  normally with the last evaluation's success (a scheduler's requeue resumes it);
- a non-finite network (``NonFiniteError``): no checkpoint, so the last good one stays the newest;
- a callback that stops the run (a sweep's pruner): its exception, unchanged;
- anything else (a full disk, a tracker that stopped answering, a bug): a checkpoint if there is
  work to keep, then ``TrainingError`` in one line naming the cause and where to resume from.
"""

from __future__ import annotations

import contextlib
import math
import signal
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn, Protocol

from rlgrasp.errors import ConfigError
from rlgrasp.rundir import RunLockedError, run_lock
from rlgrasp.train.algorithm import NonFiniteError
from rlgrasp.train.callbacks import Callback
from rlgrasp.train.preemption import StopSignals
from rlgrasp.train.tracking.logger import log


class TrainingError(RuntimeError):
    """Training stopped on a fault (env crash, NaN, a failed evaluation process); the message says
    what and where."""


class Stopped(Exception):
    """A stop signal arrived: save and leave the loop."""


class CallbackStop(Exception):
    """Carries what ``on_eval`` raised (a sweep's pruner) past the loop's fault handler, to be
    re-raised unchanged by ``train``."""

    def __init__(self, raised: BaseException) -> None:
        super().__init__(repr(raised))
        self.raised = raised


class Evaluated(Protocol):
    """What the lifecycle reads of a run's evaluations (``rlgrasp.train.evaluation.evaluations``, which
    raise this module's exceptions, so it is not imported here): the last one's metrics, if any."""

    last: dict[str, Any] | None


class Run(Protocol):
    """What the lifecycle reads of a run (``rlgrasp.train.loop.Trainer``)."""

    run_dir: Path
    ckpt_dir: Path
    frames: int
    frames_at_start: int
    logger: Any
    evaluations: Evaluated
    callbacks: list[Callback]
    signals: StopSignals

    def begin(self) -> None: ...

    def save(self, is_best: bool = False) -> None: ...


@dataclass
class Ending:
    """What ``run()`` returns when a stop signal ended the run: the last evaluation's success."""

    success: float = math.nan


@contextlib.contextmanager
def guarded(run: Run) -> Iterator[Ending]:
    """The run's body inside the run directory's lock and the stop signals' handlers: a stop signal
    saves and ends the body without an exception (read ``Ending.success`` after the ``with``); every
    other ending saves or not, and raises, as the module's docstring lists."""
    ending = Ending()
    with contextlib.ExitStack() as cleanup:
        try:
            cleanup.enter_context(run_lock(run.run_dir))
        except RunLockedError as exc:
            run.logger.close()
            raise ConfigError(str(exc)) from None
        cleanup.callback(run.logger.close)
        for callback in run.callbacks:
            cleanup.callback(callback.close)
        run.begin()
        cleanup.enter_context(run.signals)
        try:
            yield ending
        except (KeyboardInterrupt, Stopped):
            stopped_by = run.signals.received
            why = signal.Signals(stopped_by).name if stopped_by else "interrupted"
            log.warning("%s at %s frames: saving a checkpoint", why, f"{run.frames:,}")
            run.save()
            ending.success = float((run.evaluations.last or {}).get("success_rate", math.nan))
        except NonFiniteError as exc:
            raise TrainingError(
                f"{exc} at {run.frames:,} frames; stopped without saving, the last good checkpoint "
                f"is {run.ckpt_dir / 'last.pt'}"
            ) from exc
        except CallbackStop as stop:
            raise stop.raised from None
        except (TrainingError, ConfigError):
            raise
        except Exception as exc:  # noqa: BLE001 - any other fault: keep the work, say what happened
            _fault(run, exc)


def _fault(run: Run, exc: Exception) -> NoReturn:
    """Save what can be saved, then ``TrainingError`` in one line naming the cause and where to resume
    from. Nothing new is saved before the first batch (there is nothing to lose)."""
    cause = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:300]
    if run.frames == run.frames_at_start:
        raise TrainingError(f"{cause} at {run.frames:,} frames (before the first update)") from exc
    try:
        run.save()
        kept = f"checkpoint saved; resume with resume={run.run_dir}"
    except Exception as save_exc:  # noqa: BLE001 - e.g. the same full disk
        kept = (
            f"the checkpoint could not be saved ({type(save_exc).__name__}); "
            f"the last good one is in {run.ckpt_dir}"
        )
    raise TrainingError(f"{cause} at {run.frames:,} frames; {kept}") from exc
