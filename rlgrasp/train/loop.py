"""The training core: a ``Trainer`` whose steps are collect, update, log, evaluate, checkpoint, finish,
the same for every algorithm (``rlgrasp.train.algorithm``: PPO, SAC, DAgger).

``train(cfg)`` is the entry point. The Trainer's ``state_dict()`` is the checkpoint and
``load_state_dict()`` resumes from one, so tests and tools build checkpoints through this code.
"""

from __future__ import annotations

import contextlib
import copy
import math
import random
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase

from rlgrasp.config import ConfigError
from rlgrasp.rundir import CHECKPOINTS, ENV_ERRORS, RunLockedError, run_lock
from rlgrasp.stats import wilson_interval
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.adr_sync import AdrSync
from rlgrasp.train.algorithm import Algorithm, NonFiniteError, algorithm_class
from rlgrasp.train.batches import Batches
from rlgrasp.train.collect import read_env_errors
from rlgrasp.train.collectors import begin_shutdown, shut_down
from rlgrasp.train.eval_process import EvalProcessError, background_evaluator
from rlgrasp.train.evaluate import periodic_evaluator, summarize
from rlgrasp.train.legacy import algorithm_state
from rlgrasp.train.logger import log, progress_line, setup_text_log
from rlgrasp.train.metrics import Due, Phases, Throughput, finished_episodes
from rlgrasp.train.parts import build_parts
from rlgrasp.train.preemption import StopSignals
from rlgrasp.train.resume import prepare_run
from rlgrasp.train.warm_start import warm_start
from rlgrasp.utils import flatten, keep_freed_memory

#: Called after each evaluation with (frames, metrics); see ``train``.
EvalCallback = Callable[[int, dict[str, float]], None]


class TrainingError(RuntimeError):
    """Training stopped on a fault (env crash, NaN); the message says what and where."""


class _Stopped(Exception):
    """A stop signal arrived: save and leave the loop."""


class _CallbackStop(Exception):
    """Carries what ``on_eval`` raised (a sweep's pruner) past the fault handler, to be re-raised
    unchanged by ``train``."""

    def __init__(self, raised: BaseException) -> None:
        super().__init__(repr(raised))
        self.raised = raised


def resolve_device(device: str) -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


class Trainer:
    """One training run. ``run()`` reads straight down: collect, update, log, evaluate, checkpoint,
    until the frame or time budget is spent; then the final evaluation and checkpoint. What learns
    from the batches is ``self.algo`` (``algo._target_``)."""

    def __init__(
        self, cfg: DictConfig, on_eval: EvalCallback | None = None, resumed: dict[str, Any] | None = None
    ) -> None:
        """``cfg`` as ``rlgrasp.train.resume.prepare_run`` returns it, ``resumed`` the checkpoint."""
        self.cfg, self.on_eval = cfg, on_eval
        self.phases = Phases()  # where the wall clock goes, from the launch: train.log's last line
        self.run_dir = Path(cfg.paths.output_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        setup_text_log(self.run_dir)
        self.ckpt_dir, self.error_dir = self.run_dir / CHECKPOINTS, self.run_dir / ENV_ERRORS
        self.config = OmegaConf.to_container(cfg, resolve=True)
        self.device = resolve_device(cfg.device)
        torch.set_num_threads(cfg.collector.torch_threads)
        self.signals = StopSignals()  # entered by run(): a stop signal saves and ends the run

        # --- parts: seeded first, so the same seed gives the same initial networks
        seed_everything(cfg.seed)
        try:
            self.parts = build_parts(cfg, self.device)
        except (ValueError, TypeError, OSError) as exc:  # the env refuses its keywords or object files
            raise ConfigError(f"env: {exc}".splitlines()[0]) from exc
        stagger = self.parts.collector.stagger_starts
        full_length = OmegaConf.select(cfg.env, "sim.max_episode_steps") if stagger else None
        self.adr = AdrSync.from_env_cfg(self.config["env"], full_length)
        self.algo: Algorithm = algorithm_class(cfg.algo)(cfg, self.parts, self.device)
        self.actor = self.algo.actor
        torch.set_num_threads(self.algo.learner_threads)
        keep_freed_memory()  # the learner's per-step tensors reuse the heap (rlgrasp.utils)

        # --- counters, possibly resumed
        self.frames, self.generation = 0, 0
        self.best_success, self.last_eval = -math.inf, None
        if resumed is not None:
            self.load_state_dict(resumed)
            log.info("resumed from %s at %s frames", cfg.resume, f"{self.frames:,}")
        elif cfg.algo.get("init_from"):
            log.info(warm_start(self.actor, cfg.algo.init_from, cfg.env, cfg.model))

        # The class logger._target_ names (rlgrasp.train.logger, .trackers), given the run's own arguments.
        self.logger = instantiate(cfg.logger, _partial_=True, _convert_="all")(
            run_dir=self.run_dir, config=self.config, resumed_frames=None if resumed is None else self.frames
        )
        if resumed is None:
            self.logger.text("config", OmegaConf.to_yaml(self.config), 0)
        self.evaluator = periodic_evaluator(self.parts.make_env, cfg)
        self.background = background_evaluator(cfg, self.evaluator, self.actor)  # None: in this process
        self.final_episodes = cfg.eval.final_episodes or cfg.eval.episodes

    @property
    def updates(self) -> int:
        """The algorithm's update count (saved in checkpoints as ``updates``)."""
        return self.algo.updates

    @updates.setter
    def updates(self, value: int) -> None:
        self.algo.updates = value

    # --- checkpoint state ---------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """The checkpoint (its layout is documented in ``rlgrasp.train.checkpoint``): the core's
        entries and the algorithm's own."""
        state = {
            "format": ckpt_lib.FORMAT,
            "actor": self.actor.state_dict(),
            self.algo.name: self.algo.state_dict(),  # each algorithm's under its own key
            "frames": self.frames,
            "updates": self.algo.updates,
            "generation": self.generation,
            "best_eval_success": self.best_success,
            "last_eval": self.last_eval,
            "rng": ckpt_lib.rng_state(),
            "config": self.config,
            "spec": self.parts.spec,
            "versions": ckpt_lib.package_versions(),
            "run_dir": str(self.run_dir),
        }
        if self.parts.kind == "vision":  # how evaluation and export rebuild the policy
            state["kind"] = "vision"
        if self.adr is not None:
            state["adr"] = self.adr.state.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from a checkpoint: weights, the algorithm's state, RNG, counters; the generation
        moves on."""
        saved = (state.get("config") or {}).get("algo", {}).get("name")
        if saved is not None and saved != self.algo.name:
            raise ConfigError(
                f"algo: the checkpoint was trained with algo={saved}, not algo={self.algo.name}; "
                f"resume it with algo={saved}, or start a new run (algo.init_from=<checkpoint> to warm start)"
            )
        try:
            self.actor.load_state_dict(state["actor"])
            self.algo.updates = state["updates"]
            self.algo.load_state_dict(_algorithm_state(state))
        except (RuntimeError, KeyError) as exc:
            raise ConfigError(
                f"checkpoint does not fit the model: {str(exc).splitlines()[-1].strip()[:200]}"
            ) from exc
        try:
            ckpt_lib.set_rng_state(state["rng"])
        except (KeyError, TypeError, ValueError, AttributeError, RuntimeError) as exc:
            raise ConfigError(f"checkpoint's rng state is unreadable ({type(exc).__name__}: {exc})") from None
        self.frames = state["frames"]
        self.generation = state.get("generation", 0) + 1
        self.best_success = state.get("best_eval_success", -math.inf)
        self.last_eval = state.get("last_eval")
        if self.adr is not None and "adr" in state:
            self.adr.state.load_state_dict(state["adr"])

    def save(self, is_best: bool = False) -> None:
        with self.phases("checkpoints"):
            self._save(is_best)

    def _save(self, is_best: bool) -> None:
        # What the checkpoint goes with first (a replay file): a checkpoint on disk always has it.
        self.algo.save_extra(self.run_dir)
        path = ckpt_lib.write_checkpoints(
            self.ckpt_dir, self.state_dict(), self.cfg.checkpoint.keep_last, is_best
        )
        log.info("checkpoint %s", path)
        if self.adr is not None:  # the ranges reached so far, for rlgrasp-eval
            self.adr.write_ranges(self.run_dir)

    # --- the run --------------------------------------------------------------------------------
    def run(self) -> float:
        """Train; returns the final evaluation success rate (NaN if the env has none)."""
        with contextlib.ExitStack() as cleanup:
            try:
                cleanup.enter_context(run_lock(self.run_dir))
            except RunLockedError as exc:
                self.logger.close()
                raise ConfigError(str(exc)) from None
            cleanup.callback(self.logger.close)
            cleanup.callback(self.evaluator.close)
            if self.background is not None:
                cleanup.callback(self.background.close)
            log.info(
                "run dir %s | %s | device %s | %d frames per batch (%s) | %s",
                self.run_dir,
                self.algo.name,
                self.device,
                self.parts.frames_per_batch,
                type(self.parts.collector).__name__,
                self.parts.spec,
            )
            self.start = time.monotonic()  # the time budget includes the workers' start-up
            self.phases.mark("start-up")  # from the launch: the interpreter, imports, env spec, networks
            cleanup.enter_context(self.signals)
            if self.updates == 0 and self.frames == 0:
                self.algo.start(self.logger.scalars)
            self.frames_at_start = self.frames
            try:
                # a finished run, or an algorithm that learns without env frames (bc_only), starts no workers
                if self.frames < self.cfg.total_frames and self.algo.collects:
                    with self._collector() as batches:
                        self._loop(batches)
                        with self.phases("shutdown"):
                            batches.close()  # a batch in flight (a time budget's end) arrives
                            begin_shutdown(batches.collector)  # the workers end during the final eval
                        return self.finish()
                return self.finish()
            except (KeyboardInterrupt, _Stopped):
                stopped_by = self.signals.received
                why = signal.Signals(stopped_by).name if stopped_by else "interrupted"
                log.warning("%s at %s frames: saving a checkpoint", why, f"{self.frames:,}")
                self.save()
                return float((self.last_eval or {}).get("success_rate", float("nan")))
            except NonFiniteError as exc:
                raise TrainingError(
                    f"{exc} at {self.frames:,} frames; stopped without saving, the last good checkpoint "
                    f"is {self.ckpt_dir / 'last.pt'}"
                ) from exc
            except _CallbackStop as stop:
                raise stop.raised from None
            except (TrainingError, ConfigError):
                raise
            except Exception as exc:  # noqa: BLE001 - any other fault: keep the work, say what happened
                self._fault(exc)

    def _fault(self, exc: Exception) -> NoReturn:
        """An unexpected exception in the loop (a tracker that stopped answering, a full disk, a bug):
        save what can be saved, then ``TrainingError`` in one line naming the cause and where to
        resume from. Nothing new is saved before the first batch (there is nothing to lose)."""
        cause = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:300]
        if self.frames == self.frames_at_start:
            raise TrainingError(f"{cause} at {self.frames:,} frames (before the first update)") from exc
        try:
            self.save()
            kept = f"checkpoint saved; resume with resume={self.run_dir}"
        except Exception as save_exc:  # noqa: BLE001 - e.g. the same full disk
            kept = (
                f"the checkpoint could not be saved ({type(save_exc).__name__}); "
                f"the last good one is in {self.ckpt_dir}"
            )
        raise TrainingError(f"{cause} at {self.frames:,} frames; {kept}") from exc

    def _check_stop(self) -> None:
        if self.signals.received is not None:
            raise _Stopped

    @contextlib.contextmanager
    def _collector(self) -> Iterator[Batches]:
        """The collector's batches (``rlgrasp.train.batches``); its workers are shut down however the
        loop ends."""
        behaviour = copy.deepcopy(self.algo.behaviour)
        with self.phases("first batch"):  # the workers' start-up: spawned, imports, envs built
            collector = self.parts.make_collector(self.generation, str(self.error_dir), behaviour)
        backend = self.parts.collector
        batches = Batches(
            collector,
            self.algo.behaviour,
            behaviour,
            backend.collects_ahead,
            self.adr,
            timeout_s=None if backend.in_process else backend.worker_timeout_s,
        )
        try:
            yield batches
        finally:
            with self.phases("shutdown"):
                batches.close()
                shut_down(collector)

    def _loop(self, batches: Batches) -> None:
        cfg = self.cfg
        budget_s = cfg.time_budget_min * 60 if cfg.time_budget_min else math.inf
        eval_due = Due(cfg.eval.interval_frames, self.frames)
        ckpt_due = Due(cfg.checkpoint.interval_frames, self.frames)
        throughput = Throughput()
        self.recent: dict[str, float] = {}
        start = self.start
        while self.frames < cfg.total_frames and time.monotonic() - start < budget_s:
            self._check_stop()
            batches.ahead = self.frames + self.parts.frames_per_batch < cfg.total_frames  # else: the last
            t0 = time.perf_counter()
            with self.phases("first batch" if throughput.t0 is None else "collection"):
                batch = self.collect(batches)
            self._check_stop()  # a batch collected while stopping is neither trained on nor counted
            self.frames += batch.numel()
            metrics = {"time/collect_s": time.perf_counter() - t0, **self.episode_metrics(batch)}
            with self.phases("updates"):
                metrics.update(self.update(batch))
            if self.adr is not None:
                metrics.update(self.adr.scalars())
            metrics["charts/SPS"] = sps = throughput(batch.numel(), t0)
            with self.phases("logging"):
                self.logger.scalars(metrics, self.frames)
                self.peek_eval()

            is_best = False
            if eval_due(self.frames) and self.frames < cfg.total_frames:  # the final eval runs at the end
                with self.phases("periodic evaluations"):
                    is_best = self.periodic_eval()
            if ckpt_due(self.frames) or is_best:
                self.save(is_best)
            with self.phases("logging"):
                self.logger.progress(self.progress(sps, budget_s - (time.monotonic() - start)))
        with self.phases("periodic evaluations"):
            self.pick_up_eval()  # the one still in the background, before the final one

    def collect(self, batches: Iterator[TensorDictBase]) -> TensorDictBase:
        """The next batch, flattened to ``[envs * workers, time]`` (not yet counted in ``frames``: the
        loop counts it once it is sure to train on it); an env crash saves a checkpoint and says which env."""
        try:
            batch = next(batches)
        except (KeyboardInterrupt, StopIteration):
            raise
        except Exception as exc:
            self.save()
            time.sleep(0.5)  # let the failing worker finish writing its report
            self._check_stop()  # the workers got the stop signal too (a scheduler signals them all)
            reports = read_env_errors(self.error_dir) or [f"{type(exc).__name__}: {exc}"]
            raise TrainingError(
                f"collection failed at {self.frames:,} frames; checkpoint saved in {self.ckpt_dir}\n  "
                + "\n  ".join(reports)
            ) from exc
        return batch.reshape(-1, batch.shape[-1])

    def update(self, batch: TensorDictBase) -> dict[str, float]:
        """The algorithm's update on a counted batch (the workers get the weights from ``Batches``);
        a non-finite parameter stops the run before it reaches a checkpoint."""
        metrics = self.algo.update(batch, self.frames)
        self.algo.check_finite()
        return {k if "/" in k else f"losses/{k}": v for k, v in metrics.items()}

    def episode_metrics(self, batch: TensorDictBase) -> dict[str, float]:
        """Return, length and success of the episodes that ended in this batch (for the console too)."""
        stagger = self.parts.collector.stagger_starts
        full_length = OmegaConf.select(self.cfg.env, "sim.max_episode_steps") if stagger else None
        ep = finished_episodes(batch, full_length, self.parts.spec.get("reward_terms", ()))
        for key in ("charts/episodic_return", "charts/success_rate"):
            if key in ep:
                self.recent[key] = ep[key]
        return ep

    def progress(self, sps: float, budget_left_s: float) -> str:
        """The console's progress line (the logger shows it every ``logger.console_interval_s``)."""
        eta = min((self.cfg.total_frames - self.frames) / max(sps, 1e-9), budget_left_s)
        eval_success = self.last_eval.get("success_rate") if self.last_eval else None
        return progress_line(
            self.frames,
            self.cfg.total_frames,
            sps,
            self.recent.get("charts/success_rate"),
            self.recent.get("charts/episodic_return"),
            eval_success,
            eta,
        )

    def evaluate(self, final: bool = False) -> bool:
        """Deterministic evaluation of the current weights in this process (the final one shared with
        the evaluation process when there is one: ``_play_final``); logs it, reports it to
        ``on_eval``; returns whether it is the best.

        An exception from ``on_eval`` (a sweep's pruner) saves a checkpoint and propagates.
        """
        t0 = time.perf_counter()
        episodes = self.final_episodes if final else self.cfg.eval.episodes
        self.actor.eval()
        try:
            result = self._play_final(episodes) if final else None
            if result is None:
                result = self.evaluator.run(self.actor, episodes)
        finally:
            self.actor.train()
        is_best = self.record_eval(result, self.frames, episodes, time.perf_counter() - t0, final)
        self.report_eval(result, self.frames, lambda: self.save(is_best))
        return is_best

    def _play_final(self, episodes: int) -> dict[str, float] | None:
        """The final evaluation split with the evaluation process, if ``eval.background`` started one:
        it plays the later rounds on a copy of the weights while this process plays the first ones,
        and the episodes are joined in order, so the figures are those of one process (the collector's
        workers are gone by then: the process has a core to itself). None: no process to share with."""
        bg, rounds = self.background, self.evaluator.rounds(episodes)
        if bg is None or not bg.running or bg.pending is not None or rounds < 2:
            return None
        mine = (rounds + 1) // 2
        try:
            bg.submit(self.frames, self.actor.state_dict(), episodes, part=(mine, rounds - mine))
        except EvalProcessError as exc:
            self._eval_process_failed(exc)
        played = self.evaluator.play(self.actor, episodes, 0, mine)
        return summarize([played, self._wait_for_background()[1]], episodes)

    def _wait_for_background(self) -> tuple[Any, Any]:
        """The evaluation process's pending evaluation and its result, once it has arrived; a stop
        signal meanwhile ends the wait (``_Stopped``), a failed process ends the run."""
        try:
            done = self.background.wait(stop=lambda: self.signals.received is not None)
        except EvalProcessError as exc:
            self._eval_process_failed(exc)
        if done is None:
            raise _Stopped
        return done

    def periodic_eval(self) -> bool:
        """The evaluation due now; returns whether the checkpoint to save now is the best.

        With ``eval.background`` the previous one is picked up first (``pick_up_eval``) and this one
        starts in the evaluation process on the current weights, kept with a copy of the whole state
        (what ``best.pt`` gets if it is the best); training goes on meanwhile.
        """
        if self.background is None:
            return self.evaluate()
        self.pick_up_eval()
        try:
            self.background.submit_state(self.frames, self.state_dict(), self.cfg.eval.episodes)
        except EvalProcessError as exc:
            self._eval_process_failed(exc)
        return False

    def peek_eval(self) -> None:
        """Log the background evaluation's figures as soon as they have arrived (the learner checks
        after each batch), so a curve against the wall clock shows them when they were known; what
        depends on them (``last_eval``, ``best.pt``, ``on_eval``) waits for ``pick_up_eval``, at a fixed
        point of the loop."""
        done = None if self.background is None else self.background.ready()
        if done is not None and done[0].logged is None and done[0].part is None:
            pending, result = done
            pending.logged = self.log_eval(result, pending.frames, pending.episodes, self.background.seconds)

    def pick_up_eval(self) -> None:
        """Wait for the background evaluation, if one is under way, and record it at the frames of
        the weights it evaluated: a fixed point of the loop, so one seed still gives one run."""
        bg = self.background
        if bg is None or bg.pending is None:
            return
        t0 = time.perf_counter()
        pending, result = self._wait_for_background()
        self.logger.scalars({"time/eval_wait_s": time.perf_counter() - t0}, self.frames)
        if pending.logged is None:
            pending.logged = self.log_eval(result, pending.frames, pending.episodes, bg.seconds)
        is_best = self.keep_eval(pending.logged, pending.frames, pending.episodes)
        if is_best:  # the weights that were evaluated, with this evaluation's bookkeeping
            pending.keep.update(last_eval=self.last_eval, best_eval_success=self.best_success)
            path = ckpt_lib.save_checkpoint(self.ckpt_dir / "best.pt", pending.keep)
            log.info("checkpoint %s (the weights of %s frames)", path, f"{pending.frames:,}")
        self.report_eval(result, pending.frames, self.save)

    def _eval_process_failed(self, exc: EvalProcessError) -> NoReturn:
        self._check_stop()  # a scheduler's signal reached the evaluation process too: a stop
        self.save()
        where = f"at {self.frames:,} frames; checkpoint saved in {self.ckpt_dir}"
        raise TrainingError(f"{exc}\n  {where}") from exc

    def record_eval(
        self, result: dict[str, float], frames: int, episodes: int, seconds: float, final: bool = False
    ) -> bool:
        """Log an evaluation of the weights of ``frames`` at ``frames``; keep it as ``last_eval``;
        returns whether it is the best so far."""
        return self.keep_eval(self.log_eval(result, frames, episodes, seconds, final), frames, episodes)

    def log_eval(
        self, result: dict[str, float], frames: int, episodes: int, seconds: float, final: bool = False
    ) -> dict[str, float]:
        """Log an evaluation at ``frames`` (with the algorithm's extras); returns what was logged."""
        result = {**result, **self.algo.eval_extras(result, self.evaluator.run, episodes)}
        self.logger.scalars({f"eval/{k}": v for k, v in result.items()}, frames)
        self.logger.scalars({"time/eval_s": seconds}, frames)
        log.info("eval at %s frames: %s", f"{frames:,}", {k: round(v, 3) for k, v in result.items()})
        if final and "success_rate" in result:
            wins = round(result["success_rate"] * episodes)
            low, high = wilson_interval(wins, episodes)
            log.info("final eval: success %d/%d [95%% Wilson %.3f, %.3f]", wins, episodes, low, high)
        return result

    def keep_eval(self, result: dict[str, float], frames: int, episodes: int) -> bool:
        """Keep a logged evaluation as ``last_eval``; returns whether it is the best so far."""
        self.last_eval = {**result, "frames": frames, "episodes": episodes}
        score = result.get("success_rate", result["mean_reward"])
        is_best = score > self.best_success
        if is_best:
            self.best_success = score
        return is_best

    def report_eval(self, result: dict[str, float], frames: int, save: Callable[[], None]) -> None:
        """``on_eval(frames, result)``; an exception from it calls ``save`` and propagates."""
        if self.on_eval is None:
            return
        try:
            self.on_eval(frames, {**result, "frames": frames})
        except BaseException as exc:
            log.warning("stopped by the eval callback at %s frames: %r", f"{self.frames:,}", exc)
            save()
            if isinstance(exc, Exception):  # past the fault handler, unchanged (``run`` unwraps it)
                raise _CallbackStop(exc) from exc
            raise

    def finish(self) -> float:
        """Final evaluation (unless the last one is current) and checkpoint; hparams; the result."""
        last = self.last_eval
        if last is None or last["frames"] != self.frames or self.final_episodes > self.cfg.eval.episodes:
            with self.phases("final evaluation"):
                is_best = self.evaluate(final=True)
            self.save(is_best)
        elif (
            not (self.ckpt_dir / "last.pt").exists()
            or ckpt_lib.load_checkpoint(self.run_dir, user=self.config)["frames"] != self.frames
        ):
            self.save()
        result = self.last_eval or {}
        success = float(result.get("success_rate", float("nan")))
        self.logger.hparams(
            flatten(self.config),
            {
                "hparam/eval_success_rate": success,
                "hparam/eval_mean_reward": result.get("mean_reward", float("nan")),
            },
        )
        log.info("finished at %s frames: eval %s", f"{self.frames:,}", result)
        log.info(self.phases.line())
        return success


def train(cfg: DictConfig, on_eval: EvalCallback | None = None, changed: set[str] | None = None) -> float:
    """Train PPO as configured; returns the final evaluation success rate (NaN if the env has none).

    Raises ``TrainingError`` on an env crash (after saving a checkpoint) or a NaN/inf (keeping the
    last good checkpoint), ``ConfigError``/``CheckpointError`` on bad input before anything starts.
    Ctrl-C, SIGTERM, SIGUSR1 and SIGUSR2 save a checkpoint and return normally (under SLURM or
    submitit after requeueing the job; a Python handler the signal had before, e.g. a sweep's, is
    called after the checkpoint and may raise). ``changed``: the keys the command line set, for a resume
    (None: all of ``cfg``; see ``rlgrasp.train.resume``).

    ``on_eval(frames, metrics)`` runs after every evaluation (periodic and final); a sweep uses it to
    report to its pruner. An exception it raises (e.g. ``optuna.TrialPruned``) stops training: a
    checkpoint is saved, workers are shut down, and the exception propagates unchanged.
    """
    cfg, resumed = prepare_run(cfg, changed)
    trainer = Trainer(cfg, on_eval, resumed)
    result = trainer.run()
    trainer.signals.after_checkpoint(finished=trainer.frames >= cfg.total_frames)
    return result


def _algorithm_state(state: dict[str, Any]) -> dict[str, Any]:
    """The algorithm's part of a checkpoint (an older one's mapped by ``rlgrasp.train.legacy``)."""
    found = algorithm_state(state)
    if found is None:
        raise KeyError("the checkpoint holds no training state of its algorithm")
    return found
