"""PPO on the training core: ``rlgrasp.algos.ppo.learner.PPOLearner``'s update, its learning-rate schedule,
the critic's warm-up, and the auxiliary terms its config names (``algo.terms``: DAPG's imitation of
``algo.demos``, a camera student's imitation of a teacher, RND's curiosity), each built by its own
class."""

from __future__ import annotations

import time
from typing import Any

import torch
from hydra.utils import get_class

from rlgrasp.algos.ppo.learner import Extra, PPOLearner
from rlgrasp.demos.bc import pretrain
from rlgrasp.demos.dataset import demos_for
from rlgrasp.train.algorithm import Algorithm


class PPO(Algorithm):
    """Clipped PPO with GAE (``algo=ppo``); its checkpoint state (under ``ppo``) keeps ``critic``,
    ``optimizer`` and each term with a state of its own (``rnd``) by the names they always had, so a
    checkpoint written before, with them at the top level, resumes through the same code."""

    name = "ppo"

    def __init__(self, cfg: Any, parts: Any, device: torch.device) -> None:
        super().__init__(cfg, parts, device)
        self.critic = parts.critic
        a = cfg.algo
        # The demonstrations are read, and refused, here: before any worker starts.
        self.demos = demos_for(a.demos, parts.make_env, cfg.env) if a.get("demos") else None
        self.terms = self._terms()
        self.learner = PPOLearner(
            self.actor,
            parts.critic,
            parts.norms,
            a,
            device,
            stale_batches=parts.collector.collects_ahead,
            extras=list(self.terms.values()),
        )

    def _terms(self) -> dict[str, Extra]:
        """Each ``algo.terms`` node built by the class its ``_target_`` names (``from_config(node,
        algorithm)``), in the config's order; a term that is off builds to None and is left out."""
        terms = {}
        for name, node in self.cfg.algo.get("terms", {}).items():
            term = get_class(node._target_).from_config(node, self)
            if term is not None:
                terms[name] = term
        return terms

    @property
    def collects(self) -> bool:
        """Behaviour cloning alone (``algo.pretrain.only``) starts no workers."""
        return not self.cfg.algo.pretrain.only

    def start(self, log_scalars: Any) -> None:
        a = self.cfg.algo
        if self.demos is not None and a.pretrain.epochs:
            metrics = pretrain(self.actor, self.critic, self.parts.norm, self.demos, a.pretrain, a.loss.gamma)
            log_scalars(metrics, 0)

    def update(self, batch: Any, frames: int) -> dict[str, float]:
        """One PPO round at the scheduled learning rate."""
        t1 = time.perf_counter()
        lr = self.learner.lr_at(frames, self.cfg.total_frames)
        self.learner.set_lr(lr)
        self.learner.actor_frozen = frames <= self.cfg.algo.schedule.critic_warmup_frames
        metrics = self.learner.update(batch, self.updates)
        self.updates += 1
        metrics.setdefault("charts/learning_rate", lr)  # the learner's: its minibatches' mean rate
        metrics["time/train_s"] = time.perf_counter() - t1
        return metrics

    def check_finite(self) -> None:
        self.learner.check_params()

    def state_dict(self) -> dict[str, Any]:
        state = {"critic": self.critic.state_dict(), "optimizer": self.learner.optimizer.state_dict()}
        for name, term in self.terms.items():
            if isinstance(term, torch.nn.Module):  # a term with weights of its own
                state[name] = term.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.critic.load_state_dict(state["critic"])
        for name, term in self.terms.items():
            if isinstance(term, torch.nn.Module):
                term.load_state_dict(state[name])
        self.learner.optimizer.load_state_dict(state["optimizer"])
