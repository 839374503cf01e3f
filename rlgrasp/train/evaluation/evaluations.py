"""Training's evaluations, beside the loop rather than inside it: the periodic ones (in the learner's
process, or in the evaluation process while training goes on), the final one, their curves, the last
and the best result, the best checkpoint of a background evaluation, and the ``on_eval`` callback a
sweep's pruner listens on.

The loop calls four hooks (``on_batch_end``, ``on_eval_due``, ``on_loop_end``, ``on_train_end``) and
hands itself as ``host``: the frames counted, the actor, ``save`` and ``state_dict``, the checkpoint
folder and whether a stop signal arrived. That is all an evaluation needs of training, the way a
lightning callback is given its trainer.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn, Protocol

from omegaconf import DictConfig

from rlgrasp.stats import wilson_interval
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.callbacks import Callback
from rlgrasp.train.evaluation.eval_process import EvalProcessError, background_evaluator
from rlgrasp.train.evaluation.evaluate import EnvFactory, periodic_evaluator, summarize
from rlgrasp.train.lifecycle import CallbackStop, Stopped, TrainingError
from rlgrasp.train.tracking.logger import log

#: Called after each evaluation with (frames, metrics); see ``rlgrasp.train.loop.train``.
EvalCallback = Callable[[int, dict[str, float]], None]


class Host(Protocol):
    """What the evaluations read of the training run (``rlgrasp.train.loop.Trainer``)."""

    frames: int
    actor: Any
    ckpt_dir: Path
    logger: Any

    def save(self, is_best: bool = False) -> None: ...

    def state_dict(self) -> dict[str, Any]: ...

    def stop_requested(self) -> bool: ...


class Evaluations(Callback):
    """The evaluations of one run and what they decide: ``last`` (the latest result, saved in every
    checkpoint), ``best_success`` (which checkpoint is ``best.pt``)."""

    def __init__(
        self, cfg: DictConfig, make_env: EnvFactory, actor: Any, algo: Any, on_eval: EvalCallback | None
    ):
        self.evaluator = periodic_evaluator(make_env, cfg)
        self.background = background_evaluator(cfg, self.evaluator, actor)  # None: in this process
        self.episodes = cfg.eval.episodes
        self.final_episodes = cfg.eval.final_episodes or cfg.eval.episodes
        self.algo, self.on_eval = algo, on_eval
        self.best_success, self.last = -math.inf, None

    def close(self) -> None:
        self.evaluator.close()
        if self.background is not None:
            self.background.close()

    # --- checkpoint state ---------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {"best_eval_success": self.best_success, "last_eval": self.last}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.best_success = state.get("best_eval_success", -math.inf)
        self.last = state.get("last_eval")

    # --- the loop's hooks ---------------------------------------------------------------------
    def on_batch_end(self, host: Host, metrics: dict[str, float]) -> None:
        """Log the background evaluation's figures as soon as they have arrived, so a curve against
        the wall clock shows them when they were known; what depends on them (``last``, ``best.pt``,
        ``on_eval``) waits for ``on_eval_due`` or ``on_loop_end``, at a fixed point of the loop."""
        done = None if self.background is None else self.background.ready()
        if done is not None and done[0].logged is None and done[0].part is None:
            pending, result = done
            pending.logged = self._log(
                host, result, pending.frames, pending.episodes, self.background.seconds
            )

    def on_eval_due(self, host: Host) -> bool:
        """The periodic evaluation due now; returns whether the checkpoint to save now is the best.

        With ``eval.background`` the previous one is picked up first and this one starts in the
        evaluation process on the current weights, kept with a copy of the whole state (what
        ``best.pt`` gets if it is the best); training goes on meanwhile.
        """
        if self.background is None:
            return self.evaluate(host)
        self.on_loop_end(host)
        try:
            self.background.submit_state(host.frames, host.state_dict(), self.episodes)
        except EvalProcessError as exc:
            self._process_failed(host, exc)
        return False

    def on_loop_end(self, host: Host) -> None:
        """Wait for the background evaluation, if one is under way, and record it at the frames of
        the weights it evaluated: a fixed point of the loop, so one seed still gives one run."""
        bg = self.background
        if bg is None or bg.pending is None:
            return
        t0 = time.perf_counter()
        pending, result = self._wait(host)
        host.logger.scalars({"time/eval_wait_s": time.perf_counter() - t0}, host.frames)
        if pending.logged is None:
            pending.logged = self._log(host, result, pending.frames, pending.episodes, bg.seconds)
        is_best = self._keep(pending.logged, pending.frames, pending.episodes)
        if is_best:  # the weights that were evaluated, with this evaluation's bookkeeping
            pending.keep.update(last_eval=self.last, best_eval_success=self.best_success)
            path = ckpt_lib.save_checkpoint(host.ckpt_dir / "best.pt", pending.keep)
            log.info("checkpoint %s (the weights of %s frames)", path, f"{pending.frames:,}")
        self._report(host, result, pending.frames, host.save)

    def on_train_end(self, host: Host) -> bool | None:
        """The final evaluation unless the last one is of these weights and as long; returns whether
        it is the best, None when none was needed."""
        last = self.last
        if last is not None and last["frames"] == host.frames and self.final_episodes <= self.episodes:
            return None
        return self.evaluate(host, final=True)

    # --- one evaluation -----------------------------------------------------------------------
    def evaluate(self, host: Host, final: bool = False) -> bool:
        """Deterministic evaluation of the current weights in this process (the final one shared with
        the evaluation process when there is one: ``_play_final``); logs it, reports it to
        ``on_eval``; returns whether it is the best. An exception from ``on_eval`` (a sweep's pruner)
        saves a checkpoint and propagates."""
        t0 = time.perf_counter()
        episodes = self.final_episodes if final else self.episodes
        host.actor.eval()
        try:
            result = self._play_final(host, episodes) if final else None
            if result is None:
                result = self.evaluator.run(host.actor, episodes)
        finally:
            host.actor.train()
        logged = self._log(host, result, host.frames, episodes, time.perf_counter() - t0, final)
        is_best = self._keep(logged, host.frames, episodes)
        self._report(host, result, host.frames, lambda: host.save(is_best))
        return is_best

    def _play_final(self, host: Host, episodes: int) -> dict[str, float] | None:
        """The final evaluation split with the evaluation process, if ``eval.background`` started one:
        it plays the later rounds on a copy of the weights while this process plays the first ones,
        and the episodes are joined in order, so the figures are those of one process (the collector's
        workers are gone by then: the process has a core to itself). None: no process to share with."""
        bg, rounds = self.background, self.evaluator.rounds(episodes)
        if bg is None or not bg.running or bg.pending is not None or rounds < 2:
            return None
        mine = (rounds + 1) // 2
        try:
            bg.submit(host.frames, host.actor.state_dict(), episodes, part=(mine, rounds - mine))
        except EvalProcessError as exc:
            self._process_failed(host, exc)
        played = self.evaluator.play(host.actor, episodes, 0, mine)
        return summarize([played, self._wait(host)[1]], episodes)

    def _wait(self, host: Host) -> tuple[Any, Any]:
        """The evaluation process's pending evaluation and its result, once it has arrived; a stop
        signal meanwhile ends the wait (``Stopped``), a failed process ends the run."""
        try:
            done = self.background.wait(stop=host.stop_requested)
        except EvalProcessError as exc:
            self._process_failed(host, exc)
        if done is None:
            raise Stopped
        return done

    def _process_failed(self, host: Host, exc: EvalProcessError) -> NoReturn:
        if host.stop_requested():  # a scheduler's signal reached the evaluation process too: a stop
            raise Stopped
        host.save()
        where = f"at {host.frames:,} frames; checkpoint saved in {host.ckpt_dir}"
        raise TrainingError(f"{exc}\n  {where}") from exc

    def _log(
        self,
        host: Host,
        result: dict[str, float],
        frames: int,
        episodes: int,
        seconds: float,
        final: bool = False,
    ) -> dict[str, float]:
        """Log an evaluation at ``frames`` (with the algorithm's extras); returns what was logged."""
        result = {**result, **self.algo.eval_extras(result, self.evaluator.run, episodes)}
        host.logger.scalars({f"eval/{k}": v for k, v in result.items()}, frames)
        host.logger.scalars({"time/eval_s": seconds}, frames)
        log.info("eval at %s frames: %s", f"{frames:,}", {k: round(v, 3) for k, v in result.items()})
        if final and "success_rate" in result:
            wins = round(result["success_rate"] * episodes)
            low, high = wilson_interval(wins, episodes)
            log.info("final eval: success %d/%d [95%% Wilson %.3f, %.3f]", wins, episodes, low, high)
        return result

    def _keep(self, result: dict[str, float], frames: int, episodes: int) -> bool:
        """Keep a logged evaluation as ``last``; returns whether it is the best so far."""
        self.last = {**result, "frames": frames, "episodes": episodes}
        score = result.get("success_rate", result["mean_reward"])
        is_best = score > self.best_success
        if is_best:
            self.best_success = score
        return is_best

    def _report(self, host: Host, result: dict[str, float], frames: int, save: Callable[[], None]) -> None:
        """``on_eval(frames, result)``; an exception from it calls ``save`` and propagates."""
        if self.on_eval is None:
            return
        try:
            self.on_eval(frames, {**result, "frames": frames})
        except BaseException as exc:
            log.warning("stopped by the eval callback at %s frames: %r", f"{host.frames:,}", exc)
            save()
            if isinstance(exc, Exception):  # past the fault handler, unchanged (``run`` unwraps it)
                raise CallbackStop(exc) from exc
            raise
