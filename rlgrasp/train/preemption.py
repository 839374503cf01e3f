"""Stop signals and preemption: training saves a checkpoint first, then lets the scheduler go on.

SLURM sends SIGTERM before preemption or at the time limit; submitit has it send SIGUSR2; a user may
send any of them, or press Ctrl-C. During training these signals only note themselves
(``StopSignals``): the loop saves a checkpoint at its next step and returns. Then ``StopSignals.
after_checkpoint`` requeues the job (through submitit's own handler, or ``scontrol requeue`` under
plain SLURM) and hands the signal on to the handler it borrowed it from (a sweep's, which stops the
sweep). The requeued job resumes in its run directory (``rlgrasp.train.resume.requeued_resume``).
"""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
from types import TracebackType
from typing import Any

log = logging.getLogger("rlgrasp.train")

#: What a scheduler sends before preemption or at a time limit (SLURM: TERM; submitit: USR2).
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGUSR1", "SIGUSR2") if hasattr(signal, n))


class StopSignals:
    """While entered, ``STOP_SIGNALS`` only set ``received``; the handlers they had before (submitit's,
    a sweep's) are kept in ``previous`` and put back on exit."""

    def __init__(self) -> None:
        self.received: int | None = None
        self.previous: dict[int, Any] = {}

    def _note(self, signum: int, frame: Any) -> None:
        self.received = signum

    def __enter__(self) -> StopSignals:
        for sig in STOP_SIGNALS:
            try:
                self.previous[sig] = signal.signal(sig, self._note)
            except ValueError:  # not the main thread: the caller handles signals
                break
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)

    def after_checkpoint(self, finished: bool) -> None:
        """Once the signal's checkpoint is saved: requeue the job unless the run is ``finished``, then
        hand the signal on (``hand_off_preemption``, ``pass_on_signal``)."""
        if self.received is None:
            return
        if not finished:
            hand_off_preemption(self.received, self.previous)
        pass_on_signal(self.received, self.previous)


def hand_off_preemption(signum: int, previous: dict[int, Any]) -> None:
    """After the checkpoint of a stop signal: under submitit, its own checkpoint-and-requeue handler
    (SLURM: ``scontrol requeue``; submitit_local: restart), which exits; under plain SLURM,
    ``scontrol requeue $SLURM_JOB_ID``. Elsewhere nothing: the process exits normally.

    A job SLURM requeues by itself (``scontrol requeue``, preemption) is already pending when the
    signal arrives, so submitit's own requeue fails; that job exits without a result too: a result
    would tell submitit (and the Hydra sweep waiting on it) the run ended at the preempted frames."""
    submitit = [h for h in previous.values() if getattr(h, "__name__", "") == "checkpoint_and_try_requeue"]
    if submitit:
        log.warning("handing over to submitit to requeue the job")
        try:
            submitit[0](signum, None)  # exits (SystemExit) once the job is requeued
        except Exception as exc:  # noqa: BLE001 - e.g. scontrol refusing a job SLURM already requeues
            if slurm_requeued_already():
                log.warning("SLURM requeues the job itself; exiting without a result for the rerun to write")
                sys.exit(-1)  # what submitit does after its own requeue
            log.warning("requeue through submitit failed: %s", exc)
        return
    job = os.environ.get("SLURM_JOB_ID")
    if job:
        proc = subprocess.run(["scontrol", "requeue", job], capture_output=True, text=True, timeout=60)
        log.warning("scontrol requeue %s: %s", job, (proc.stderr or proc.stdout).strip() or "requeued")


def slurm_requeued_already() -> bool:
    """SLURM requeued this job while it still runs (``scontrol requeue``, preemption): its restart
    count is past this run's ``SLURM_RESTART_COUNT`` (the job shows COMPLETING meanwhile, and
    ``scontrol requeue`` from inside it answers "Job is pending execution")."""
    job = os.environ.get("SLURM_JOB_ID")
    if not job:
        return False
    try:
        proc = subprocess.run(
            ["scontrol", "-o", "show", "job", job], capture_output=True, text=True, timeout=60
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    restarts = re.search(r"\bRestarts=(\d+)", proc.stdout)
    return restarts is not None and int(restarts.group(1)) > int(os.environ.get("SLURM_RESTART_COUNT") or 0)


def pass_on_signal(signum: int, previous: dict[int, Any]) -> None:
    """Training only borrows a stop signal to save first: a Python handler installed before it (a
    sweep's) gets it too, so a SIGTERM stops the whole sweep and not only its current trial.
    Submitit's handlers are ``hand_off_preemption``'s."""
    handler = previous.get(signum)
    if callable(handler) and not getattr(handler, "__module__", "").startswith("submitit"):
        handler(signum, None)
