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
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase

from rlgrasp import policy_file
from rlgrasp.config import ConfigError
from rlgrasp.envs.factory import episode_steps
from rlgrasp.legacy import algorithm_state
from rlgrasp.rundir import CHECKPOINTS, ENV_ERRORS, RunLockedError, run_lock
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.adr_sync import AdrSync
from rlgrasp.train.algorithm import Algorithm, NonFiniteError, algorithm_class
from rlgrasp.train.batches import Batches
from rlgrasp.train.collect import read_env_errors
from rlgrasp.train.collectors import begin_shutdown, shut_down
from rlgrasp.train.evaluations import CallbackStop, EvalCallback, Evaluations, Stopped, TrainingError
from rlgrasp.train.logger import log, progress_line, setup_text_log
from rlgrasp.train.metrics import Due, Phases, Throughput, finished_episodes
from rlgrasp.train.parts import build_parts
from rlgrasp.train.preemption import StopSignals
from rlgrasp.train.resume import prepare_run
from rlgrasp.train.warm_start import warm_start
from rlgrasp.utils import flatten, keep_freed_memory

__all__ = ["EvalCallback", "Trainer", "TrainingError", "train"]


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
        # With staggered starts only episodes of full length count (read once: env=gym asks gym's registry)
        self.full_length = episode_steps(cfg.env) if stagger else None
        self.adr = AdrSync.from_env_cfg(self.config["env"], self.full_length)
        self.algo: Algorithm = algorithm_class(cfg.algo)(cfg, self.parts, self.device)
        self.actor = self.algo.actor
        torch.set_num_threads(self.algo.learner_threads)
        keep_freed_memory()  # the learner's per-step tensors reuse the heap (rlgrasp.utils)
        # Beside the loop: periodic and final evaluations, their curves, last and best, best.pt.
        self.evaluations = Evaluations(cfg, self.parts.make_env, self.actor, self.algo, on_eval)

        # --- counters, possibly resumed
        self.frames, self.generation = 0, 0
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
            "format": policy_file.CHECKPOINT_FORMAT,
            "actor": self.actor.state_dict(),
            self.algo.name: self.algo.state_dict(),  # each algorithm's under its own key
            "frames": self.frames,
            "updates": self.algo.updates,
            "generation": self.generation,
            **self.evaluations.state_dict(),  # best_eval_success, last_eval
            "rng": ckpt_lib.rng_state(),
            "config": self.config,
            "spec": self.parts.spec,
            "versions": policy_file.package_versions(),
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
        self.evaluations.load_state_dict(state)
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
            cleanup.callback(self.evaluations.close)
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
            except (KeyboardInterrupt, Stopped):
                stopped_by = self.signals.received
                why = signal.Signals(stopped_by).name if stopped_by else "interrupted"
                log.warning("%s at %s frames: saving a checkpoint", why, f"{self.frames:,}")
                self.save()
                return float((self.evaluations.last or {}).get("success_rate", float("nan")))
            except NonFiniteError as exc:
                raise TrainingError(
                    f"{exc} at {self.frames:,} frames; stopped without saving, the last good checkpoint "
                    f"is {self.ckpt_dir / 'last.pt'}"
                ) from exc
            except CallbackStop as stop:
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

    def stop_requested(self) -> bool:
        return self.signals.received is not None

    def _check_stop(self) -> None:
        if self.stop_requested():
            raise Stopped

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
                self.evaluations.on_batch_end(self)

            is_best = False
            if eval_due(self.frames) and self.frames < cfg.total_frames:  # the final eval runs at the end
                with self.phases("periodic evaluations"):
                    is_best = self.evaluations.on_eval_due(self)
            if ckpt_due(self.frames) or is_best:
                self.save(is_best)
            with self.phases("logging"):
                self.logger.progress(self.progress(sps, budget_s - (time.monotonic() - start)))
        with self.phases("periodic evaluations"):
            self.evaluations.on_loop_end(self)  # the one still in the background, before the final one

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
        ep = finished_episodes(batch, self.full_length, self.parts.spec.get("reward_terms", ()))
        for key in ("charts/episodic_return", "charts/success_rate"):
            if key in ep:
                self.recent[key] = ep[key]
        return ep

    def progress(self, sps: float, budget_left_s: float) -> str:
        """The console's progress line (the logger shows it every ``logger.console_interval_s``)."""
        eta = min((self.cfg.total_frames - self.frames) / max(sps, 1e-9), budget_left_s)
        last = self.evaluations.last
        eval_success = last.get("success_rate") if last else None
        return progress_line(
            self.frames,
            self.cfg.total_frames,
            sps,
            self.recent.get("charts/success_rate"),
            self.recent.get("charts/episodic_return"),
            eval_success,
            eta,
        )

    def finish(self) -> float:
        """Final evaluation (unless the last one is current) and checkpoint; hparams; the result."""
        with self.phases("final evaluation"):
            is_best = self.evaluations.on_train_end(self)
        if is_best is not None:
            self.save(is_best)
        elif (
            not (self.ckpt_dir / "last.pt").exists()
            or policy_file.load_checkpoint(self.run_dir, user=self.config)["frames"] != self.frames
        ):
            self.save()
        result = self.evaluations.last or {}
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
    """The algorithm's part of a checkpoint (an older one's mapped by ``rlgrasp.legacy``)."""
    found = algorithm_state(state)
    if found is None:
        raise KeyError("the checkpoint holds no training state of its algorithm")
    return found
