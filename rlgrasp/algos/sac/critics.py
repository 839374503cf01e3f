"""SAC's and TQC's critics as one batched network: every critic's layer is one slice of a stacked
weight, and a forward pass over all of them is one matrix product per layer (``torch.baddbmm`` over
``[critics, batch, features]``; the first layer, whose input the critics share, a single GEMM).

Why not TorchRL's ensemble: ``SACLoss`` keeps one critic module and swaps each critic's parameters
into it on every call (``torch.vmap`` over ``functional_call``, the parameters moved in and out as a
TensorDict), several times a gradient step; on a CPU at minibatch 256 that bookkeeping cost about as
much as the critics' arithmetic. Here the parameters live in the layers that use them.

The stacked parameters keep the shapes and names TorchRL gave them (``mlp.<i>.weight`` of shape
``[critics, out, in]``, ``mlp.<i>.bias`` ``[critics, out]``, a LayerNorm's ``[critics, width]``), so a
checkpoint written with ``SACLoss`` maps onto them by renaming alone (``rlgrasp.algos.sac.losses``), and
its optimizer state, which follows the parameters' order, loads as it is.

The single critic of that earlier layout, the template TorchRL's losses copied, is the reference the
tests hold these critics and their losses against (``tests/sac_reference.py``).
"""

from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn

from rlgrasp.models.mlp import ACTIVATIONS, RunningNorm


class EnsembleLinear(nn.Module):
    """``critics`` independent linear layers, each initialized as ``nn.Linear`` is."""

    def __init__(self, critics: int, in_features: int, out_features: int) -> None:
        super().__init__()
        layers = [nn.Linear(in_features, out_features) for _ in range(critics)]
        self.weight = nn.Parameter(torch.stack([layer.weight.detach() for layer in layers]))
        self.bias = nn.Parameter(torch.stack([layer.bias.detach() for layer in layers]))

    def forward(self, x: torch.Tensor, detach: bool = False) -> torch.Tensor:
        """``x``: ``[batch, in]`` (the same input for every critic) or ``[critics, batch, in]``;
        returns ``[critics, batch, out]``. ``detach``: the parameters read without gradient (the
        actor's loss differentiates through the critics, not into them)."""
        weight, bias = (self.weight.detach(), self.bias.detach()) if detach else (self.weight, self.bias)
        critics, out, inp = weight.shape
        if x.dim() == 2:  # shared input: one GEMM onto every critic's units at once
            y = F.linear(x, weight.reshape(critics * out, inp), bias.reshape(critics * out))
            return y.view(x.shape[0], critics, out).transpose(0, 1)
        return torch.baddbmm(bias.unsqueeze(1), x, weight.transpose(1, 2))


class EnsembleLayerNorm(nn.Module):
    """``critics`` independent LayerNorms over the last dimension of ``[critics, batch, width]``."""

    def __init__(self, critics: int, width: int, eps: float = 1e-5) -> None:
        super().__init__()
        self.eps = eps
        self.weight = nn.Parameter(torch.ones(critics, width))
        self.bias = nn.Parameter(torch.zeros(critics, width))

    def forward(self, x: torch.Tensor, detach: bool = False) -> torch.Tensor:
        weight, bias = (self.weight.detach(), self.bias.detach()) if detach else (self.weight, self.bias)
        normed = F.layer_norm(x, x.shape[-1:], eps=self.eps)
        return torch.addcmul(bias.unsqueeze(1), normed, weight.unsqueeze(1))


class CriticEnsemble(nn.Module):
    """``critics`` Q-networks Q(s, a) as one module: an MLP on the normalized state and the rest of the
    inputs (a camera's image features, then the action), LayerNorm after each hidden layer when asked
    (RLPD: what keeps critics stable at several updates per frame), ``outputs`` values each.

    The normalizer is the actor's, held by reference and not as a submodule: the critics must read the
    running statistics the actor (and so the deployed policy) uses, and their state dict is theirs."""

    def __init__(
        self,
        norm: RunningNorm,
        critics: int,
        in_dim: int,
        hidden: list[int],
        activation: str,
        layer_norm: bool,
        outputs: int = 1,
    ) -> None:
        super().__init__()
        object.__setattr__(self, "norm", norm)  # a reference, not a submodule (see above)
        layers: list[nn.Module] = []
        width = in_dim
        for size in hidden:  # QNet's layers and indices, so the parameters' names are its
            layers += [
                EnsembleLinear(critics, width, size),
                *([EnsembleLayerNorm(critics, size)] if layer_norm else []),
                ACTIVATIONS[activation](),
            ]
            width = size
        layers.append(EnsembleLinear(critics, width, outputs))  # Q, or a distributional critic's atoms
        self.mlp = nn.Sequential(*layers)
        self.critics = critics

    def forward(self, state: torch.Tensor, *rest: torch.Tensor, detach: bool = False) -> torch.Tensor:
        """Every critic's values ``[critics, batch, outputs]`` of the state and the rest of the inputs
        (each ``[batch, features]``); ``detach``: through the critics but not into their parameters."""
        x = torch.cat([self.norm(state), *rest], dim=-1)
        for layer in self.mlp:
            x = layer(x, detach) if isinstance(layer, (EnsembleLinear, EnsembleLayerNorm)) else layer(x)
        return x

    def frozen_copy(self) -> CriticEnsemble:
        """A copy without gradients (the target critics) that reads the same normalizer."""
        twin = copy.deepcopy(self, memo={id(self.norm): self.norm})
        return twin.requires_grad_(False)
