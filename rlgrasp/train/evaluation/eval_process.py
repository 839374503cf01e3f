"""Training's periodic evaluation in a process of its own, beside collection and learning.

The learner hands over a copy of the actor's weights (``submit``) and goes on training; the spawned
process runs ``rlgrasp.train.evaluation.evaluate.Evaluator.run`` on them, the same code on the same seeded
episodes as the in-process evaluation, so a snapshot gets the numbers the learner would have
computed. The learner picks the result up (``wait``) at a point its loop fixes (the next evaluation
due, the end of training), never "whenever it arrives", so one seed still gives one run.

Hand-written rather than TorchRL 0.14's ``torchrl.collectors.Evaluator`` (process backend): that one
collects ``num_trajectories`` complete episodes with a collector, so which episodes it gets depends on
which envs finish first, and it does not re-seed the envs for each evaluation; it would not evaluate
the same seeded episodes as ``Evaluator.run``, and switching evaluation to the background would
change training's numbers.
"""

from __future__ import annotations

import copy
import io
import logging
import multiprocessing
import signal
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import torch

from rlgrasp.config import PeriodicEvalConfig
from rlgrasp.train.evaluation.evaluate import Evaluator
from rlgrasp.utils import SpawnContextIgnoringCtrlC, die_with_parent

log = logging.getLogger("rlgrasp.train")
#: How often ``wait`` checks whether to stop waiting.
POLL_S = 0.2
#: How long ``close`` lets an idle process end by itself before killing it.
CLOSE_TIMEOUT_S = 10.0


class EvalProcessError(RuntimeError):
    """The evaluation process failed (an env raised) or died (a signal, out of memory)."""


@dataclass
class Pending:
    """An evaluation under way: the frames its weights belong to, its episodes, and what the learner
    asked to keep with it (a checkpoint of that moment, saved as ``best.pt`` if it is the best)."""

    frames: int
    episodes: int
    keep: Any = None
    #: ``(first_round, rounds)`` when the process plays only those rounds of the evaluation (its
    #: answer is then ``Evaluator.play``'s per-episode figures, not the metrics); None: all of it.
    part: tuple[int, int] | None = None
    #: The metrics as logged when the result arrived (``Evaluations.on_batch_end``); None: not yet logged.
    logged: dict[str, float] | None = None


def _to_bytes(obj: Any) -> bytes:
    """Tensors as ``torch.save`` bytes: a pipe would otherwise move them into shared memory, and the
    process would see the learner's later updates of the same storage."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _serve(conn: Connection) -> None:
    """The process: for each request ``(weights bytes, episodes, part)``, ``evaluator.run`` on the
    policy with those weights (or, ``part`` = ``(first_round, rounds)``, ``evaluator.play`` of those
    rounds); answers ``("ok", metrics or figures, seconds)`` or ``("error", message, traceback)``. Ends
    on ``None`` or when the learner's end of the pipe closes."""
    # Born ignoring Ctrl-C (it reaches the whole process group): the learner decides when this
    # process ends, or its death does. The evaluator and the policy come through the pipe.
    die_with_parent()
    try:
        evaluator, policy, threads = conn.recv()
    except (EOFError, OSError):  # the learner is gone before it sent them
        return
    torch.set_num_threads(threads)  # as the learner's: the same kernels, the same numbers
    policy.eval()
    try:
        while (request := conn.recv()) is not None:
            weights, episodes, part = request
            t0 = time.perf_counter()
            try:
                policy.load_state_dict(torch.load(io.BytesIO(weights), weights_only=True))
                if part is None:
                    result = evaluator.run(policy, episodes)
                else:
                    result = evaluator.play(policy, episodes, *part)
                answer = ("ok", result, time.perf_counter() - t0)
            except Exception as exc:  # noqa: BLE001 - reported to the learner, which stops training
                answer = ("error", f"{type(exc).__name__}: {exc}", traceback.format_exc())
            conn.send(answer)
    except (EOFError, OSError):  # the learner is gone
        pass
    finally:
        evaluator.close()


class BackgroundEvaluator:
    """One evaluation at a time in a spawned process (started at the first ``submit``).

    ``policy``: a module of the actor's architecture (copied; the weights come with each ``submit``),
    run on the CPU with ``threads`` torch threads. ``close`` always ends the process.
    """

    def __init__(self, evaluator: Evaluator, policy: torch.nn.Module, threads: int | None = None) -> None:
        self.evaluator = evaluator
        self.policy = copy.deepcopy(policy).cpu()
        self.threads = threads or torch.get_num_threads()
        self.pending: Pending | None = None
        self.seconds = 0.0  # the last evaluation's duration in its process
        self._proc: multiprocessing.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._answer: Any = None  # an answer ``ready`` received before ``wait``

    @property
    def running(self) -> bool:
        """Whether the process has been started (it is, from the first ``submit`` on)."""
        return self._proc is not None

    def _start(self) -> None:
        ctx = SpawnContextIgnoringCtrlC()  # a forked child would share PyBullet and torch state
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(child,), name="rlgrasp-eval", daemon=True)
        self._proc.start()
        child.close()
        self._conn.send((self.evaluator, self.policy, self.threads))
        log.info("periodic evaluations run in process %d", self._proc.pid)

    def submit(
        self,
        frames: int,
        weights: dict[str, torch.Tensor],
        episodes: int,
        keep: Any = None,
        part: tuple[int, int] | None = None,
    ) -> None:
        """Evaluate ``weights`` (the actor's ``state_dict`` at ``frames``) on ``episodes`` episodes, or
        play only rounds ``part`` = ``(first_round, rounds)`` of that evaluation (the learner plays
        the others: ``Evaluator.play``)."""
        if self.pending is not None:
            raise RuntimeError("an evaluation is pending: wait() for it first")
        if self._proc is None:
            self._start()
        payload = _to_bytes({k: v.detach().cpu() for k, v in weights.items()})
        try:
            self._conn.send((payload, episodes, part))
        except OSError as exc:
            raise EvalProcessError(f"the evaluation process is gone ({self._exit()})") from exc
        self.pending = Pending(frames, episodes, keep, part)
        self._answer = None

    def submit_state(self, frames: int, state: dict[str, Any], episodes: int) -> None:
        """``submit`` the actor of a copy of the whole training ``state``, kept with the evaluation:
        if it is the best, ``best.pt`` gets that state, not the one training has moved on to."""
        snapshot = copy.deepcopy(state)
        self.submit(frames, snapshot["actor"], episodes, keep=snapshot)

    def ready(self) -> tuple[Pending, dict[str, float]] | None:
        """The pending evaluation's ``(pending, metrics)`` if its result has arrived, without waiting
        (it stays pending: ``wait`` still hands it over); None if it has not, or none is pending."""
        if self.pending is None:
            return None
        if self._answer is None:
            try:
                if not self._conn.poll(0):
                    return None
                self._answer = self._conn.recv()
            except (EOFError, OSError):
                return None  # ``wait`` says the process died
        if self._answer[0] != "ok":
            return None
        self.seconds = self._answer[2]
        return self.pending, self._answer[1]

    def wait(self, stop: Callable[[], bool] = lambda: False) -> tuple[Pending, Any] | None:
        """Block until the pending evaluation's result arrives: ``(pending, metrics)`` (``part``: the
        rounds' figures); None as soon as ``stop()`` is true (a stop signal: the evaluation is left to
        ``close``)."""
        if self.pending is None:
            raise RuntimeError("no evaluation is pending")
        try:
            if self._answer is None:
                while not self._conn.poll(POLL_S):
                    if stop():
                        return None
                self._answer = self._conn.recv()
        except (EOFError, OSError) as exc:
            self.pending = None
            raise EvalProcessError(f"the evaluation process died ({self._exit()})") from exc
        answer, self._answer = self._answer, None
        pending, self.pending = self.pending, None
        if answer[0] == "error":
            log.warning("the evaluation process failed:\n%s", answer[2])
            raise EvalProcessError(f"the evaluation failed: {answer[1]}")
        _, metrics, self.seconds = answer
        return pending, metrics

    def _exit(self) -> str:
        self._proc.join(1.0)
        code = self._proc.exitcode
        if code is not None and code < 0:
            return f"killed by {signal.Signals(-code).name}"
        return "still running" if code is None else f"exit code {code}"

    def close(self) -> None:
        """End the process: at once if an evaluation is under way (its result is dropped), else after
        it has closed its envs."""
        if self._proc is None:
            return
        busy = self.pending is not None and self._answer is None
        self.pending = self._answer = None
        try:
            if not busy:
                self._conn.send(None)
        except OSError:
            pass
        self._proc.join(0 if busy else CLOSE_TIMEOUT_S)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        self._conn.close()
        self._proc = self._conn = None


def background_evaluator(
    cfg: Any, evaluator: Evaluator, policy: torch.nn.Module
) -> BackgroundEvaluator | None:
    """``evaluator`` in its own process if the training config sets ``eval.background`` (a resumed run's
    older config, without the key, takes the schema's default), else None."""
    if not cfg.eval.get("background", PeriodicEvalConfig.background):
        return None
    return BackgroundEvaluator(evaluator, policy, torch.get_num_threads())
