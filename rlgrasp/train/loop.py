"""The training core: a ``Trainer`` whose steps are collect, update, log, evaluate, checkpoint, finish,
the same for every algorithm (``rlgrasp.train.algorithm``: PPO, SAC, DAgger).

``train(cfg)`` is the entry point. The Trainer's ``state_dict()`` is the checkpoint and
``load_state_dict()`` resumes from one, so tests and tools build checkpoints through this code.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase

from rlgrasp import policy_file
from rlgrasp.config import ConfigError
from rlgrasp.envs.factory import episode_steps
from rlgrasp.legacy import algorithm_state
from rlgrasp.rundir import CHECKPOINTS, ENV_ERRORS
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.algorithm import Algorithm, algorithm_class
from rlgrasp.train.callbacks import Callback
from rlgrasp.train.collection.adr_sync import AdrSync
from rlgrasp.train.collection.batches import Batches
from rlgrasp.train.collection.collect import read_env_errors
from rlgrasp.train.collection.collectors import begin_shutdown
from rlgrasp.train.evaluation.evaluations import EvalCallback, Evaluations
from rlgrasp.train.lifecycle import Stopped, TrainingError, guarded
from rlgrasp.train.parts import build_parts
from rlgrasp.train.preemption import StopSignals
from rlgrasp.train.resume import prepare_run
from rlgrasp.train.tracking.logger import final_metrics, log, progress_line, setup_text_log
from rlgrasp.train.tracking.metrics import Due, Phases, Throughput, finished_episodes
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
        # Beside the loop: periodic and final evaluations, their curves, last and best, best.pt; ADR.
        self.evaluations = Evaluations(cfg, self.parts.make_env, self.actor, self.algo, on_eval)
        self.callbacks: list[Callback] = [c for c in (self.evaluations, self.adr) if c is not None]

        # --- counters, possibly resumed
        self.frames, self.generation = 0, 0
        if resumed is not None:
            self.load_state_dict(resumed)
            log.info("resumed from %s at %s frames", cfg.resume, f"{self.frames:,}")
        elif cfg.algo.get("init_from"):
            log.info(warm_start(self.actor, cfg.algo.init_from, cfg.env, cfg.model))

        # The class logger._target_ names (rlgrasp.train.tracking), given the run's own arguments.
        self.logger = instantiate(cfg.logger, _partial_=True, _convert_="all")(
            run_dir=self.run_dir, config=self.config, resumed_frames=None if resumed is None else self.frames
        )
        if resumed is None:
            self.logger.text("config", OmegaConf.to_yaml(self.config), 0)

    @property
    def updates(self) -> int:
        """The algorithm's update count (saved in checkpoints as ``updates``)."""
        return self.algo.updates

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
            "rng": ckpt_lib.rng_state(),
            "config": self.config,
            "spec": self.parts.spec,
            "versions": policy_file.package_versions(),
            "run_dir": str(self.run_dir),
        }
        if self.parts.kind == "vision":  # how evaluation and export rebuild the policy
            state["kind"] = "vision"
        for callback in self.callbacks:  # best_eval_success, last_eval; adr
            state.update(callback.state_dict())
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from a checkpoint: weights, the algorithm's state, RNG, counters; the generation
        moves on."""
        ckpt_lib.check_algorithm(state, self.algo.name)
        try:
            self.actor.load_state_dict(state["actor"])
            self.algo.updates = state["updates"]
            self.algo.load_state_dict(_algorithm_state(state))
        except (RuntimeError, KeyError) as exc:
            raise ConfigError(
                f"checkpoint does not fit the model: {str(exc).splitlines()[-1].strip()[:200]}"
            ) from exc
        ckpt_lib.restore_rng(state)
        self.frames = state["frames"]
        self.generation = state.get("generation", 0) + 1
        for callback in self.callbacks:
            callback.load_state_dict(state)

    def save(self, is_best: bool = False) -> None:
        """A checkpoint, after what goes with it (a replay file: a checkpoint on disk always has it)."""
        with self.phases("checkpoints"):
            self.algo.save_extra(self.run_dir)
            state, keep = self.state_dict(), self.cfg.checkpoint.keep_last
            log.info("checkpoint %s", ckpt_lib.write_checkpoints(self.ckpt_dir, state, keep, is_best))
            for callback in self.callbacks:
                callback.on_save(self.run_dir)

    # --- the run --------------------------------------------------------------------------------
    def run(self) -> float:
        """Train; returns the final evaluation success rate (NaN if the env has none). How a run
        ends other than by its budget (a signal, a NaN, a fault) is ``rlgrasp.train.lifecycle``'s."""
        with guarded(self) as ending:
            return self.fit()
        return ending.success  # a stop signal ended it, after a checkpoint

    def begin(self) -> None:
        """Say what runs, and start the clock: the time budget includes the workers' start-up."""
        log.info(
            "run dir %s | %s | device %s | %d frames per batch (%s) | %s",
            self.run_dir,
            self.algo.name,
            self.device,
            self.parts.frames_per_batch,
            type(self.parts.collector).__name__,
            self.parts.spec,
        )
        self.start = time.monotonic()
        self.phases.mark("start-up")  # from the launch: the interpreter, imports, env spec, networks
        self.frames_at_start = self.frames

    def fit(self) -> float:
        """The algorithm's start (e.g. cloning demonstrations), the loop, the final evaluation and
        checkpoint. A finished run, or an algorithm that learns without env frames (bc_only), starts
        no workers."""
        if self.updates == 0 and self.frames == 0:
            self.algo.start(self.logger.scalars)
        if self.frames < self.cfg.total_frames and self.algo.collects:
            opened = self.parts.open_batches(
                self.algo.behaviour, self.generation, self.error_dir, self.adr, self.phases
            )
            with opened as batches:
                self._loop(batches)
                with self.phases("shutdown"):
                    batches.close()  # a batch in flight (a time budget's end) arrives
                    begin_shutdown(batches.collector)  # the workers end during the final eval
                return self.finish()
        return self.finish()

    def stop_requested(self) -> bool:
        return self.signals.received is not None

    def _check_stop(self) -> None:
        if self.stop_requested():
            raise Stopped

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
            metrics["charts/SPS"] = sps = throughput(batch.numel(), t0)
            with self.phases("logging"):
                for callback in self.callbacks:  # ADR's curves; a background evaluation's figures
                    callback.on_batch_end(self, metrics)
                self.logger.scalars(metrics, self.frames)

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
        seen, last_eval = self.recent.get, (self.evaluations.last or {}).get("success_rate")
        success, ret = seen("charts/success_rate"), seen("charts/episodic_return")
        return progress_line(self.frames, self.cfg.total_frames, sps, success, ret, last_eval, eta)

    def finish(self) -> float:
        """Final evaluation (unless the last one is current) and checkpoint; hparams; the result."""
        with self.phases("final evaluation"):
            is_best = self.evaluations.on_train_end(self)
        if is_best is not None:
            self.save(is_best)
        elif (
            not (self.ckpt_dir / "last.pt").exists()
            or not ckpt_lib.numbered_path(self.ckpt_dir, self.frames).exists()
        ):
            self.save()
        result = self.evaluations.last or {}
        self.logger.hparams(flatten(self.config), final_metrics(result))
        log.info("finished at %s frames: eval %s", f"{self.frames:,}", result)
        log.info(self.phases.line())
        return float(result.get("success_rate", float("nan")))


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
