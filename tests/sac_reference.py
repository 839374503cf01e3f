"""The critic of the layout before ``rlgrasp.algos.sac.critics``: one network that TorchRL's
``SACLoss`` / ``TQCLoss`` copied into their ensemble. The reference the tests hold the batched critics
and the hand-written losses against (tests/test_losses.py); nothing in the package builds it."""

from __future__ import annotations

from typing import Any

import torch
from tensordict.nn import TensorDictModule
from torch import nn

from rlgrasp.models.mlp import ACTIVATIONS, RunningNorm


class QNet(nn.Module):
    """One critic as TorchRL's ``SACLoss`` took it (a template it copied into its ensemble): the
    layout checkpoints written before ``CriticEnsemble`` name."""

    def __init__(
        self,
        norm: RunningNorm,
        in_dim: int,
        hidden: list[int],
        activation: str,
        layer_norm: bool,
        outputs: int = 1,
    ) -> None:
        super().__init__()
        object.__setattr__(self, "norm", norm)  # a reference, not a submodule
        layers: list[nn.Module] = []
        width = in_dim
        for size in hidden:
            layers += [
                nn.Linear(width, size),
                *([nn.LayerNorm(size)] if layer_norm else []),
                ACTIVATIONS[activation](),
            ]
            width = size
        layers.append(nn.Linear(width, outputs))
        self.mlp = nn.Sequential(*layers)

    def forward(self, observation: torch.Tensor, *rest: torch.Tensor) -> torch.Tensor:
        return self.mlp(torch.cat([self.norm(observation), *rest], dim=-1))


def build_qvalue(
    norm: RunningNorm, in_keys: list[Any], in_dim: int, critic_cfg: Any, outputs: int = 1
) -> TensorDictModule:
    """A ``QNet`` as ``algo.critic`` describes it, as a TorchRL loss reads it ."""
    c = critic_cfg
    net = QNet(norm, in_dim, list(c.hidden_sizes), c.activation, c.layer_norm, outputs)
    return TensorDictModule(net, in_keys=in_keys, out_keys=["state_action_value"])
