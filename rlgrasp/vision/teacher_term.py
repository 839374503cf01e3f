"""The teacher's imitation term inside PPO: fine-tuning a camera student without forgetting.

PPO fine-tuning of a distilled student (``algo.init_from``) starts with a fresh critic, and its first
advantages pull the student away from what it learned by imitation faster than reward teaches it
anything (docs/benchmarks/cameras.md). With ``algo.terms.teacher.checkpoint`` set, the state
teacher labels every PPO minibatch's states (it reads their ``privileged`` entry, recorded for the
critic anyway), and the loss gains ``coeff * decay**k`` x the squared error between the student's
deterministic action and the teacher's at update ``k``: DAgger goes on under PPO's updates, the
anchor of DAPG (``rlgrasp.demos.bc``) with a teacher that labels any state instead of a fixed set of
demonstrations.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.demos.bc import decayed_weight, mse_bc_loss
from rlgrasp.models.spec import PRIVILEGED_KEY
from rlgrasp.policy_file import resolve_policy_path
from rlgrasp.vision.dagger import PrivilegedTeacher, load_teacher


class TeacherImitation:
    """An auxiliary term for ``PPOLearner``: the student's action regressed onto its teacher's on the
    PPO minibatch itself (the states the student visits now)."""

    def __init__(self, actor: nn.Module, teacher: PrivilegedTeacher, term: Any):
        self.actor_keys = list(actor.in_keys)
        self.teacher = teacher
        self.loss_fn = mse_bc_loss(actor)
        self.term = term
        self.weight = decayed_weight(term, 0)

    @classmethod
    def from_config(cls, term: Any, algorithm: Any) -> TeacherImitation | None:
        """The term of ``algorithm`` with the teacher ``term.checkpoint`` names (read, and refused,
        here: before any worker starts); None without one."""
        if not term.checkpoint:
            return None
        parts = algorithm.parts
        teacher, _ = load_teacher(resolve_policy_path(term.checkpoint), parts.spec, algorithm.cfg.env)
        return cls(algorithm.actor, teacher.to(algorithm.device), term)

    def trainable(self) -> list[nn.Parameter]:
        return []  # the actor's, which the PPO optimizer already holds; the teacher stays as it is

    def start(self, batch: TensorDictBase, updates: int) -> dict[str, float]:
        self.weight = decayed_weight(self.term, updates)
        return {"charts/teacher_weight": self.weight}

    def after_gae(self, batch: TensorDictBase) -> None:
        pass

    def loss(self, minibatch: TensorDictBase) -> tuple[torch.Tensor, dict[str, float]]:
        labelled = minibatch.select(*self.actor_keys, PRIVILEGED_KEY)
        self.teacher(labelled)  # writes the teacher's "action" (no gradient)
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            mse = self.loss_fn(labelled)["loss_bc"]
        return self.weight * mse, {"teacher_mse": float(mse.detach())}
