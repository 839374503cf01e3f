"""PPO on the training core: ``rlgrasp.train.ppo.PPOLearner``'s update, its learning-rate schedule,
the critic's warm-up, and the auxiliary terms a config gives it (DAPG's imitation of ``algo.demos``,
a camera student's imitation of ``algo.teacher``, RND's curiosity)."""

from __future__ import annotations

import time
from typing import Any

import torch

from rlgrasp.demos.bc import Imitation, pretrain
from rlgrasp.demos.dataset import demos_for
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.algorithm import Algorithm
from rlgrasp.train.ppo import PPOLearner
from rlgrasp.train.rnd import RND
from rlgrasp.vision.dagger import load_teacher
from rlgrasp.vision.teacher_term import TeacherImitation


class PPO(Algorithm):
    """Clipped PPO with GAE (``algo=ppo``); the checkpoint keeps ``critic``, ``optimizer`` and
    ``rnd`` where they always were, so checkpoints written before the core still resume."""

    name = "ppo"

    def __init__(self, cfg: Any, parts: Any, device: torch.device) -> None:
        super().__init__(cfg, parts, device)
        self.critic = parts.critic
        self.learner = PPOLearner(
            self.actor,
            parts.critic,
            parts.norms,
            cfg.algo,
            device,
            stale_batches=parts.collector.collects_ahead,
            extras=self._extras(),
        )

    def _extras(self) -> list[Any]:
        """The update's auxiliary terms; a demonstrations or teacher file is read, and refused, here:
        before any worker starts."""
        a, parts, extras = self.cfg.algo, self.parts, []
        self.demos = demos_for(a.demos, parts.make_env, self.cfg.env) if a.get("demos") else None
        if self.demos is not None and a.demo_coeff > 0:
            extras.append(Imitation(self.actor, self.demos, a, self.device))
        if a.get("teacher"):
            teacher, _ = load_teacher(ckpt_lib.resolve_policy_path(a.teacher), parts.spec, self.cfg.env)
            extras.append(TeacherImitation(self.actor, teacher.to(self.device), a))
        self.rnd = RND(parts.spec["obs_dim"], parts.norm, a).to(self.device) if a.get("rnd_coeff") else None
        return extras + ([self.rnd] if self.rnd is not None else [])

    @property
    def collects(self) -> bool:
        """Behaviour cloning alone (``algo.bc_only``) starts no workers."""
        return not self.cfg.algo.get("bc_only")

    def start(self, log_scalars: Any) -> None:
        if self.demos is not None and self.cfg.algo.bc_epochs:
            log_scalars(pretrain(self.actor, self.critic, self.parts.norm, self.demos, self.cfg.algo), 0)

    def update(self, batch: Any, frames: int) -> dict[str, float]:
        """One PPO round at the scheduled learning rate."""
        t1 = time.perf_counter()
        lr = self.learner.lr_at(frames, self.cfg.total_frames)
        self.learner.set_lr(lr)
        self.learner.actor_frozen = frames <= self.cfg.algo.get("critic_warmup_frames", 0)
        metrics = self.learner.update(batch, self.updates)
        self.updates += 1
        metrics.setdefault("charts/learning_rate", lr)  # the learner's: its minibatches' mean rate
        metrics["time/train_s"] = time.perf_counter() - t1
        return metrics

    def check_finite(self) -> None:
        self.learner.check_params()

    def state_dict(self) -> dict[str, Any]:
        state = {"critic": self.critic.state_dict(), "optimizer": self.learner.optimizer.state_dict()}
        if self.rnd is not None:
            state["rnd"] = self.rnd.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.critic.load_state_dict(state["critic"])
        if self.rnd is not None:
            self.rnd.load_state_dict(state["rnd"])
        self.learner.optimizer.load_state_dict(state["optimizer"])
