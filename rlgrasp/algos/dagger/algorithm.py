"""Teacher-student distillation by DAgger: a camera policy learns to act as a state policy would.

The workers step camera envs; the teacher (a state checkpoint) reads each frame's privileged state
and labels it with its action; the student (``rlgrasp.models.cnn``) sees only proprioception and
the images. Early on the teacher acts (``beta`` near 1) so the data shows what success looks like;
``beta`` decays each batch so that the student soon acts and the teacher labels the states the
student itself visits (Ross et al. 2011). Every labelled frame is kept (up to
``algo.replay.buffer_frames``) and the student is regressed onto the labels with TorchRL's
``BCLoss``. With ``algo.optim.ema_decay`` the
policy that acts, is evaluated and is saved as ``actor`` is a moving average of the trained weights:
the last snapshot of a regressed student varies from update to update, the average less
(docs/history/cameras.md#cube-wrist-depth-64x64-visualdefault-teacher-policiesgrasp_ppopt).
"""

from __future__ import annotations

import copy
import math
import time
from typing import Any

import torch
from omegaconf import DictConfig
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp import policy_file
from rlgrasp.config import ConfigError
from rlgrasp.demos.bc import mse_bc_loss
from rlgrasp.models.cnn import actor_norm, average_weights
from rlgrasp.models.spec import PRIVILEGED_KEY
from rlgrasp.train.algorithm import Algorithm
from rlgrasp.train.loop import train
from rlgrasp.vision.augment import augment
from rlgrasp.vision.auxiliary import ObjectFromImages
from rlgrasp.vision.dagger import LABEL_KEY, DAggerPolicy, LabelledFrames, load_teacher


class DAgger(Algorithm):
    """DAgger on the training core (``algo=distill``): the student is the parts' camera actor, the
    workers run the student/teacher mixture, the core evaluates ``actor`` (the averaged student)
    beside the teacher on the same seeded episodes. The labelled frames are not in checkpoints, so
    a resumed run aggregates anew."""

    name = "distill"

    def __init__(self, cfg: Any, parts: Any, device: torch.device) -> None:
        super().__init__(cfg, parts, device)
        a = cfg.algo
        if parts.kind != "vision":  # the same words as a camera student's spec gives
            raise ConfigError("env.camera=null: a camera policy needs a camera (e.g. cameras=wrist_depth)")
        self.teacher, _ = load_teacher(policy_file.resolve_policy_path(a.teacher), parts.spec, cfg.env)
        self.student = parts.actor
        # What acts, is evaluated and is exported: the student's weights averaged over its recent
        # updates (algo.optim.ema_decay; 0: the student itself).
        self.actor = copy.deepcopy(self.student) if a.optim.ema_decay > 0 else self.student
        self.policy = DAggerPolicy(self.actor, self.teacher, a.schedule.beta0)
        self.loss = mse_bc_loss(self.student)
        self.aux = None
        if a.terms.aux.coeff > 0:
            encoders = self.student.module[0].module.encoders
            self.aux = ObjectFromImages(encoders, parts.spec["privileged_parts"], a.terms.aux.parts)
        params = [*self.student.parameters(), *(self.aux.parameters() if self.aux is not None else [])]
        self.optimizer = torch.optim.Adam(params, lr=a.optim.lr)
        keys = [*self.student.in_keys, *([PRIVILEGED_KEY] if self.aux is not None else [])]
        self.data = LabelledFrames(keys, a.replay.buffer_frames, a.optim.minibatch_size)
        self._teacher_evals: dict[int, dict[str, float]] = {}

    @property
    def behaviour(self) -> torch.nn.Module:
        return self.policy

    def trained_parameters(self) -> list[torch.nn.Parameter]:
        return [*self.student.parameters(), *(self.aux.parameters() if self.aux is not None else [])]

    def update(self, batch: Any, frames: int) -> dict[str, float]:
        """Add the batch to the dataset and regress the student on samples of all of it."""
        a, optim = self.cfg.algo, self.cfg.algo.optim
        t0 = time.perf_counter()
        batch = batch.reshape(-1)
        actor_norm(self.student).update(batch["observation"])
        if self.aux is not None:
            self.aux.update(batch)
        self.data.extend(batch)
        steps = max(1, math.ceil(optim.epochs * batch.numel() / optim.minibatch_size))
        lr = optim.lr * max(a.schedule.min_lr_frac, 1.0 - frames / self.cfg.total_frames)
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        total, aux_total = 0.0, 0.0
        for _ in range(steps):
            aug = a.augment
            sample = augment(self.data.sample(), aug.kind, aug.grey, aug.shift, aug.overlay)
            sample["action"] = sample[LABEL_KEY]
            with set_exploration_type(ExplorationType.DETERMINISTIC):
                loss = self.loss(sample)["loss_bc"]
            total += loss.item()
            if self.aux is not None:  # the features of the forward the action loss just ran
                aux = self.aux.loss(sample)
                aux_total += aux.item()
                loss = loss + a.terms.aux.coeff * aux
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
            if self.actor is not self.student:
                average_weights(self.actor, self.student, optim.ema_decay)
        beta = self.policy.beta.item()
        self.updates += 1
        self.policy.beta.fill_(self._beta())
        return {
            "bc_loss": total / steps,
            **({"aux_loss": aux_total / steps} if self.aux is not None else {}),
            "charts/beta": beta,
            "charts/learning_rate": lr,
            "charts/dataset_frames": len(self.data),
            "time/train_s": time.perf_counter() - t0,
        }

    def eval_extras(self, result: dict[str, float], evaluate: Any, episodes: int) -> dict[str, float]:
        """The teacher on the same seeded episodes (once per episode count: it does not change)."""
        if episodes not in self._teacher_evals:
            self._teacher_evals[episodes] = evaluate(self.teacher, episodes)
        teacher = self._teacher_evals[episodes].get("success_rate", math.nan)
        student = result.get("success_rate", math.nan)
        return {"teacher_success_rate": teacher, "student_over_teacher": student / max(teacher, 1e-9)}

    def state_dict(self) -> dict[str, Any]:
        return {
            # The weights being trained, when they differ from the deployed average (for a resume).
            "student": self.student.state_dict() if self.actor is not self.student else None,
            "aux": self.aux.state_dict() if self.aux is not None else None,
            "optimizer": self.optimizer.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("student") is not None:  # else the student is the actor the core loaded
            self.student.load_state_dict(state["student"])
        if self.aux is not None and state.get("aux") is not None:
            self.aux.load_state_dict(state["aux"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.policy.beta.fill_(self._beta())

    def _beta(self) -> float:
        """The teacher's share of the actions after ``updates`` batches."""
        schedule = self.cfg.algo.schedule
        return schedule.beta0 * schedule.beta_decay**self.updates


def distill(cfg: DictConfig, changed: set[str] | None = None) -> float:
    """Distill ``cfg.algo.teacher`` into a camera student; returns the student's final success. The
    same run as any other algorithm's (``rlgrasp.train.loop.train``), kept by this name for callers."""
    return train(cfg, changed=changed)
