"""SAC's losses (critics, actor, temperature) and the target critics' soft update, hand-written on the
batched critics of ``rlgrasp.algos.sac.critics``.

Why not TorchRL's ``SACLoss`` (and ``TQCLoss``): at rlgrasp's sizes on a CPU (minibatch 256, critics
256x256) their per-call machinery cost more than the arithmetic: the critics' parameters swapped in
and out of one module through ``vmap`` / ``functional_call`` on every critic pass, the minibatch
cloned and written as TensorDicts several times a step, a ``SoftUpdate`` walking the parameters one by
one. The formulas are TorchRL's, term for term (``tests/test_losses.py`` holds them, and their
gradients, equal to ``SACLoss``'s and ``TQCLoss``'s on the same parameters and minibatch):

- critics: each regresses onto r + gamma (1 - terminated) (min over the target critics of Q'(s', a')
  - alpha log pi(a'|s')), a' drawn from the actor; squared error summed over critics, batch mean;
- actor: alpha log pi(a|s) - min over the critics of Q(s, a), a drawn with the reparameterization,
  the critics' parameters read without gradient;
- temperature: -log alpha (log pi(a|s) + target entropy).

The actor stays TorchRL's TanhNormal policy (sampled and scored by TorchRL's ``rsample_and_log_prob``),
called on the minibatch as it is: its parameters are its own, nothing is swapped.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs import ExplorationType, set_exploration_type
from torchrl.modules.distributions.utils import rsample_and_log_prob

from rlgrasp.algos.sac.critics import CriticEnsemble

#: Where the state dict of TorchRL's ``SACLoss`` / ``TQCLoss`` (checkpoints written before these
#: losses) kept what is now ``critics`` and ``target_critics``; the rest of it (the actor, which the
#: checkpoint also keeps on its own, and settings the config gives) is not loaded.
TORCHRL_PREFIXES = {
    "qvalue_network_params.module.": "critics.",
    "target_qvalue_network_params.module.": "target_critics.",
}


class SoftActorCriticLoss(nn.Module):
    """SAC's losses on ``critics`` (and a frozen copy of them, the targets) and ``actor`` (TorchRL's
    TanhNormal policy; held by reference: its parameters are the actor's, checkpointed with it).
    ``critic_keys``: the minibatch entries the critics read before the action, the state first (the
    one the critics' normalizer applies to). A subclass changes how the critics' outputs become the
    target, the critics' error and the actor's value: TQC (``rlgrasp.algos.tqc.losses``)."""

    def __init__(
        self,
        actor: nn.Module,
        critics: CriticEnsemble,
        critic_keys: list[Any],
        gamma: float,
        alpha_init: float,
        target_entropy: float,
    ) -> None:
        super().__init__()
        object.__setattr__(self, "actor", actor)  # a reference: not in this module's state dict
        self.critics = critics
        self.target_critics = critics.frozen_copy()
        device = critics.mlp[0].weight.device
        self.log_alpha = nn.Parameter(torch.tensor(math.log(alpha_init), device=device))
        self.critic_keys = list(critic_keys)
        self.gamma = float(gamma)
        self.target_entropy = float(target_entropy)

    @property
    def alpha(self) -> torch.Tensor:
        """The temperature, without gradient (the losses other than its own read it as a constant)."""
        return self.log_alpha.detach().exp()

    def sample(self, td: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """An action drawn from the actor at ``td``'s states (reparameterized) and its log-probability."""
        with set_exploration_type(ExplorationType.RANDOM):
            dist = self.actor.get_dist(td)
        return rsample_and_log_prob(dist)

    def critic_inputs(self, td: TensorDictBase, action: torch.Tensor) -> list[torch.Tensor]:
        return [*(td.get(key) for key in self.critic_keys), action]

    @torch.no_grad()
    def target(self, td: TensorDictBase) -> torch.Tensor:
        """The critics' regression target, ``[batch, values]``: the reward plus the discounted value of
        the next state under the target critics and a next action drawn from the actor."""
        following = td.get("next")
        action, log_prob = self.sample(following)
        values = self.target_critics(*self.critic_inputs(following, action))
        next_value = self.next_value(values, log_prob)
        not_terminated = ~following.get("terminated")
        return following.get("reward") + self.gamma * not_terminated * next_value

    def next_value(self, values: torch.Tensor, log_prob: torch.Tensor) -> torch.Tensor:
        """SAC: the soft value under the most pessimistic target critic, ``[batch, 1]``."""
        return (values - self.alpha * log_prob.unsqueeze(-1)).min(0).values

    def critic_loss(self, td: TensorDictBase) -> torch.Tensor:
        """The critics' loss on a minibatch (the action taken, the target from the next state)."""
        target = self.target(td)
        values = self.critics(*self.critic_inputs(td, td.get("action")))
        return self.critic_error(values, target)

    def critic_error(self, values: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """SAC: squared error of each critic ``[critics, batch, 1]`` to ``target`` ``[batch, 1]``,
        summed over the critics, averaged over the minibatch."""
        return (values - target).square().sum(0).mean()

    def actor_loss(self, td: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """The actor's loss and the log-probabilities of the actions it drew (detached: the
        temperature's loss reads them)."""
        action, log_prob = self.sample(td)
        values = self.critics(*self.critic_inputs(td, action), detach=True)
        loss = (self.alpha * log_prob - self.actor_value(values)).mean()
        return loss, log_prob.detach()

    def actor_value(self, values: torch.Tensor) -> torch.Tensor:
        """SAC: the most pessimistic critic's Q, ``[batch]``."""
        return values.min(0).values.squeeze(-1)

    def alpha_loss(self, log_prob: torch.Tensor) -> torch.Tensor:
        """The temperature's loss: it rises while the policy's entropy is below the target, falls above."""
        return (-self.log_alpha * (log_prob + self.target_entropy)).mean()

    @torch.no_grad()
    def soft_update(self, tau: float) -> None:
        """Move the target critics ``tau`` of the way towards the critics (one fused call)."""
        torch._foreach_lerp_(list(self.target_critics.parameters()), list(self.critics.parameters()), tau)

    def load_state_dict(self, state_dict: dict[str, Any], strict: bool = True, assign: bool = False) -> Any:
        """This module's state dict, or one of TorchRL's ``SACLoss`` / ``TQCLoss`` (``from_torchrl``)."""
        return super().load_state_dict(from_torchrl(state_dict), strict=strict, assign=assign)


def from_torchrl(state: dict[str, Any]) -> dict[str, Any]:
    """A state dict of TorchRL's ``SACLoss`` / ``TQCLoss`` as ``SoftActorCriticLoss`` names it (the
    critics' stacked parameters have the same shapes; only their prefix changes); any other as it is."""
    if not any(key.startswith("qvalue_network_params.") for key in state):
        return state
    renamed = {"log_alpha": state["log_alpha"]}
    for key, value in state.items():
        for old, new in TORCHRL_PREFIXES.items():
            if key.startswith(old):
                renamed[new + key[len(old) :]] = value
    return renamed
