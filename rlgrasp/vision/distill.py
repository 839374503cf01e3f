"""Teacher-student distillation by DAgger: a camera policy learns to act as a state policy would.

The workers step camera envs; the teacher (a state checkpoint) reads each frame's privileged state
and labels it with its action; the student (``rlgrasp.vision.models``) sees only proprioception and
the images. Early on the teacher acts (``beta`` near 1) so the data shows what success looks like;
``beta`` decays each batch so that the student soon acts and the teacher labels the states the
student itself visits (Ross et al. 2011). Every labelled frame is kept (up to ``algo.buffer_frames``)
and the student is regressed onto the labels with TorchRL's ``BCLoss``. With ``algo.ema_decay`` the
policy that acts, is evaluated and is saved as ``actor`` is a moving average of the trained weights:
the last snapshot of a regressed student varies from update to update (one run's lifted 72% of 200
episodes where its average lifted 84%, docs/benchmarks/cameras.md).
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import signal
import time
from pathlib import Path
from typing import Any, NoReturn

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.config import ConfigError
from rlgrasp.demos.bc import mse_bc_loss
from rlgrasp.envs.factory import env_factory
from rlgrasp.stats import wilson_interval
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.batches import Batches
from rlgrasp.train.collectors import collector_backend, shut_down
from rlgrasp.train.eval_process import EvalProcessError, background_evaluator
from rlgrasp.train.evaluate import periodic_evaluator
from rlgrasp.train.logger import log, setup_text_log
from rlgrasp.train.loop import TrainingError, seed_everything
from rlgrasp.train.metrics import Due, finished_episodes
from rlgrasp.train.preemption import StopSignals
from rlgrasp.train.resume import prepare_run
from rlgrasp.vision.augment import augment
from rlgrasp.vision.auxiliary import ObjectFromImages
from rlgrasp.vision.dagger import LABEL_KEY, DAggerPolicy, LabelledFrames, load_teacher
from rlgrasp.vision.models import actor_norm, average_weights, build_vision_actor
from rlgrasp.vision.spec import PRIVILEGED_KEY, vision_spec


class Distiller:
    """One distillation run: collect labelled frames, regress the student, evaluate it beside its
    teacher on the same seeded episodes, checkpoint. ``resumed``: a checkpoint to continue from (the
    student, its optimizer, frames and ``beta``; the labelled frames are not in checkpoints, so a
    resumed run aggregates anew)."""

    def __init__(self, cfg: DictConfig, resumed: dict[str, Any] | None = None) -> None:
        self.cfg, a = cfg, cfg.algo
        self.run_dir = Path(cfg.paths.output_dir)
        setup_text_log(self.run_dir)
        # The student's updates, not the workers, bound a distillation run (the workers wait for
        # the next weights), so the learner takes every core by default.
        torch.set_num_threads(a.learner_threads or os.cpu_count() or 1)
        seed_everything(cfg.seed)
        self.make_env = env_factory(cfg.env)
        self.spec = vision_spec(self.make_env)
        self.teacher, _ = load_teacher(ckpt_lib.resolve_policy_path(a.teacher), self.spec, cfg.env)
        self.student = build_vision_actor(self.spec, cfg.model)
        # What acts, is evaluated and is exported: the student's weights averaged over its recent
        # updates (algo.ema_decay; 0: the student itself).
        self.deployed = copy.deepcopy(self.student) if a.ema_decay > 0 else self.student
        self.policy = DAggerPolicy(self.deployed, self.teacher, a.beta0)
        self.loss = mse_bc_loss(self.student)
        self.aux = None
        if a.aux_coeff > 0:
            encoders = self.student.module[0].module.encoders
            self.aux = ObjectFromImages(encoders, self.spec["privileged_parts"], a.aux_parts)
        params = [*self.student.parameters(), *(self.aux.parameters() if self.aux is not None else [])]
        self.optimizer = torch.optim.Adam(params, lr=a.lr)
        keys = [*self.student.in_keys, *([PRIVILEGED_KEY] if self.aux is not None else [])]
        self.data = LabelledFrames(keys, a.buffer_frames, a.minibatch_size)
        self.frames, self.batches_seen, self.generation, self.last_eval = 0, 0, 0, None
        self.best_success = -math.inf
        if resumed is not None:
            self.load_state_dict(resumed)
        self.logger = instantiate(cfg.logger, _partial_=True, _convert_="all")(
            run_dir=self.run_dir,
            config=OmegaConf.to_container(cfg, resolve=True),
            resumed_frames=self.frames if resumed is not None else None,
        )
        if resumed is None:
            self.logger.text("config", OmegaConf.to_yaml(cfg), 0)
        self.evaluator = periodic_evaluator(self.make_env, cfg)
        # The student's periodic evaluations may run in the background (eval.background); its
        # teacher's, once per episode count and kept, run here.
        self.background = background_evaluator(cfg, self.evaluator, self.deployed)
        self._teacher_evals: dict[int, dict[str, float]] = {}
        self.signals = StopSignals()

    def run(self) -> float:
        """Distill until the frame or time budget is spent (or a stop signal: checkpoint and return)."""
        with self.signals, contextlib.ExitStack() as cleanup:
            cleanup.callback(self.logger.close)
            cleanup.callback(self.evaluator.close)
            if self.background is not None:
                cleanup.callback(self.background.close)
            if self.frames < self.cfg.total_frames:
                self._loop()
            if self.signals.received is not None:
                log.warning(
                    "%s at %s frames: saving a checkpoint",
                    signal.Signals(self.signals.received).name,
                    f"{self.frames:,}",
                )
                self.save()
                return float((self.last_eval or {}).get("success_rate", math.nan))
            result = self.evaluate(self.cfg.eval.final_episodes or self.cfg.eval.episodes, final=True)
            self.save(is_best=result >= self.best_success)
            return result

    def _loop(self) -> None:
        cfg = self.cfg
        budget_s = cfg.time_budget_min * 60 if cfg.time_budget_min else math.inf
        eval_due, ckpt_due = (
            Due(cfg.eval.interval_frames, self.frames),
            Due(cfg.checkpoint.interval_frames, self.frames),
        )
        behaviour = copy.deepcopy(self.policy)
        backend = collector_backend(cfg.collector)
        collector = backend.build(
            self.make_env, behaviour, cfg.seed, self.generation, str(self.run_dir / "env_errors")
        )
        batches = Batches(collector, self.policy, behaviour, backend.collects_ahead)
        start = time.monotonic()
        try:
            while self.frames < cfg.total_frames and time.monotonic() - start < budget_s:
                t0 = time.perf_counter()
                batch = next(batches).reshape(-1)
                if self.signals.received is not None:  # a batch collected while stopping is dropped
                    return
                self.frames += batch.numel()
                metrics = {
                    "time/collect_s": time.perf_counter() - t0,
                    **finished_episodes(batch.unsqueeze(0)),
                }
                metrics.update(self.learn(batch))
                metrics["charts/SPS"] = batch.numel() / max(time.perf_counter() - t0, 1e-9)
                self.logger.scalars(metrics, self.frames)
                is_best = eval_due(self.frames) and self.frames < cfg.total_frames and self._periodic_eval()
                if ckpt_due(self.frames) or is_best:
                    self.save(is_best)
            self._pick_up_eval()  # the one still in the background, before the final one
        finally:
            batches.close()
            shut_down(collector)

    def _periodic_eval(self) -> bool:
        """The evaluation due now; whether the checkpoint to save now is the best. In the background
        (as in PPO training, ``rlgrasp.train.loop.Trainer.periodic_eval``): the previous one is picked
        up, this one starts on a copy of the current state."""
        if self.background is None:
            return self._is_best(self.evaluate(self.cfg.eval.episodes))
        if self._pick_up_eval():
            try:
                self.background.submit_state(self.frames, self.state_dict(), self.cfg.eval.episodes)
            except EvalProcessError as exc:
                self._eval_process_failed(exc)
        return False

    def _pick_up_eval(self) -> bool:
        """Wait for the background evaluation, if any, and record it at its weights' frames (a best
        one is saved as ``best.pt`` with those weights); False if a stop signal ended its process."""
        if self.background is None or self.background.pending is None:
            return True
        try:
            done = self.background.wait(stop=self._stopping)
        except EvalProcessError as exc:
            if not self._stopping():  # else a scheduler's signal reached the evaluation process too
                self._eval_process_failed(exc)
            done = None
        if done is None:
            return False  # stopping: the loop saves and returns
        pending, student = done
        if self._is_best(self.record_eval(student, pending.frames, pending.episodes)):
            pending.keep.update(last_eval=self.last_eval, best_eval_success=self.best_success)
            ckpt_lib.save_checkpoint(self.run_dir / "checkpoints" / "best.pt", pending.keep)
        return True

    def _eval_process_failed(self, exc: EvalProcessError) -> NoReturn:
        self.save()
        where = f"at {self.frames:,} frames; checkpoint saved in {self.run_dir / 'checkpoints'}"
        raise TrainingError(f"{exc}\n  {where}") from exc

    def _stopping(self) -> bool:
        return self.signals.received is not None

    def _is_best(self, success: float) -> bool:
        is_best = success > self.best_success
        self.best_success = max(self.best_success, success)
        return is_best

    def learn(self, batch) -> dict[str, float]:
        """Add the batch to the dataset and regress the student on samples of all of it."""
        a = self.cfg.algo
        t0 = time.perf_counter()
        actor_norm(self.student).update(batch["observation"])
        if self.aux is not None:
            self.aux.update(batch)
        self.data.extend(batch)
        updates = max(1, math.ceil(a.epochs * batch.numel() / a.minibatch_size))
        lr = a.lr * max(a.min_lr_frac, 1.0 - self.frames / self.cfg.total_frames)
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        total, aux_total = 0.0, 0.0
        for _ in range(updates):
            sample = augment(self.data.sample(), a.augment, a.augment_grey, a.augment_shift)
            sample["action"] = sample[LABEL_KEY]
            with set_exploration_type(ExplorationType.DETERMINISTIC):
                loss = self.loss(sample)["loss_bc"]
            total += loss.item()
            if self.aux is not None:  # the features of the forward the action loss just ran
                aux = self.aux.loss(sample)
                aux_total += aux.item()
                loss = loss + a.aux_coeff * aux
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            if self.deployed is not self.student:
                average_weights(self.deployed, self.student, a.ema_decay)
        beta = self.policy.beta.item()
        self.batches_seen += 1
        self.policy.beta.fill_(a.beta0 * a.beta_decay**self.batches_seen)
        return {
            "losses/bc_loss": total / updates,
            **({"losses/aux_loss": aux_total / updates} if self.aux is not None else {}),
            "charts/beta": beta,
            "charts/learning_rate": lr,
            "charts/dataset_frames": len(self.data),
            "time/train_s": time.perf_counter() - t0,
        }

    def evaluate(self, episodes: int, final: bool = False) -> float:
        """The student (in this process) and its teacher on the same seeded episodes; returns the
        student's success."""
        self.deployed.eval()
        student = self.evaluator.run(self.deployed, episodes)
        self.deployed.train()
        return self.record_eval(student, self.frames, episodes, final)

    def record_eval(
        self, student: dict[str, float], frames: int, episodes: int, final: bool = False
    ) -> float:
        """Log the student's evaluation of the weights of ``frames`` beside its teacher's on the same
        episodes; returns the student's success."""
        if episodes not in self._teacher_evals:
            self._teacher_evals[episodes] = self.evaluator.run(self.teacher, episodes)
        teacher = self._teacher_evals[episodes]
        s, t = student.get("success_rate", math.nan), teacher.get("success_rate", math.nan)
        self.last_eval = {**student, "teacher_success_rate": t, "frames": frames, "episodes": episodes}
        self.logger.scalars(
            {
                "eval/success_rate": s,
                "eval/mean_reward": student["mean_reward"],
                "eval/teacher_success_rate": t,
                "eval/student_over_teacher": s / max(t, 1e-9),
            },
            frames,
        )
        wins = round(s * episodes)
        low, high = wilson_interval(wins, episodes)
        log.info(
            "%seval at %s frames: student %d/%d [95%% Wilson %.3f, %.3f], teacher %.3f on the same episodes",
            "final " if final else "",
            f"{frames:,}",
            wins,
            episodes,
            low,
            high,
            t,
        )
        return s

    # --- checkpoint state ---------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """A checkpoint that evaluation, export and the GUI read like a PPO one (``kind`` says how to
        rebuild the policy)."""
        return {
            "format": ckpt_lib.FORMAT,
            "kind": "vision",
            "actor": self.deployed.state_dict(),
            # The weights being trained, when they differ from the deployed average (for a resume).
            "student": self.student.state_dict() if self.deployed is not self.student else None,
            "aux": self.aux.state_dict() if self.aux is not None else None,
            "optimizer": self.optimizer.state_dict(),
            "frames": self.frames,
            "updates": self.batches_seen,
            "generation": self.generation,
            "best_eval_success": self.best_success,
            "last_eval": self.last_eval,
            "rng": ckpt_lib.rng_state(),
            "config": OmegaConf.to_container(self.cfg, resolve=True),
            "spec": self.spec,
            "versions": ckpt_lib.package_versions(),
            "run_dir": str(self.run_dir),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        try:
            self.deployed.load_state_dict(state["actor"])
            self.student.load_state_dict(state.get("student") or state["actor"])
        except (RuntimeError, KeyError) as exc:
            raise ConfigError(
                f"checkpoint does not fit the camera student: {str(exc).splitlines()[0][:200]}"
            ) from exc
        if self.aux is not None and state.get("aux") is not None:
            self.aux.load_state_dict(state["aux"])
        self.optimizer.load_state_dict(state["optimizer"])
        ckpt_lib.set_rng_state(state["rng"])
        self.frames, self.batches_seen = state["frames"], state["updates"]
        self.generation = state.get("generation", 0) + 1
        self.best_success = state.get("best_eval_success", -math.inf)
        self.last_eval = state.get("last_eval")
        self.policy.beta.fill_(self.cfg.algo.beta0 * self.cfg.algo.beta_decay**self.batches_seen)
        log.info("resumed from %s at %s frames", self.cfg.resume, f"{self.frames:,}")

    def save(self, is_best: bool = False) -> None:
        path = ckpt_lib.write_checkpoints(
            self.run_dir / "checkpoints", self.state_dict(), self.cfg.checkpoint.keep_last, is_best
        )
        log.info("checkpoint %s", path)


def distill(cfg: DictConfig, changed: set[str] | None = None) -> float:
    """Distill ``cfg.algo.teacher`` into a camera student; returns the student's final success.
    Resume, stop signals and preemption behave as in PPO training (``rlgrasp.train.loop.train``)."""
    cfg, resumed = prepare_run(cfg, changed)
    distiller = Distiller(cfg, resumed)
    result = distiller.run()
    distiller.signals.after_checkpoint(finished=distiller.frames >= cfg.total_frames)
    return result
