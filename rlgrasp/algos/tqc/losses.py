"""TQC's losses (Kuznetsov et al. 2020): SAC's (``rlgrasp.algos.sac.losses``, why hand-written there)
with critics that output ``n_quantiles`` atoms each. The target pools every target critic's atoms,
sorts them and drops the top ``top_quantiles_to_drop_per_net`` x critics; each critic regresses its
atoms onto every kept target atom with the quantile Huber loss; the actor maximizes the mean of all
atoms. Term for term TorchRL's ``TQCLoss`` (``tests/test_losses.py`` holds them equal).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from rlgrasp.algos.sac.critics import CriticEnsemble
from rlgrasp.algos.sac.losses import SoftActorCriticLoss


class TruncatedQuantileLoss(SoftActorCriticLoss):
    """SAC's losses on quantile critics, the pooled target truncated by ``drop_per_critic`` x critics."""

    def __init__(
        self,
        actor: nn.Module,
        critics: CriticEnsemble,
        critic_keys: list[Any],
        gamma: float,
        alpha_init: float,
        target_entropy: float,
        drop_per_critic: int,
    ) -> None:
        super().__init__(actor, critics, critic_keys, gamma, alpha_init, target_entropy)
        self.drop = drop_per_critic * critics.critics

    def next_value(self, values: torch.Tensor, log_prob: torch.Tensor) -> torch.Tensor:
        """Every target critic's atoms ``[critics, batch, quantiles]`` pooled per transition, sorted,
        the top ``drop`` left out, less the entropy term: ``[batch, kept]``."""
        pooled = values.movedim(0, -2).flatten(-2)
        kept = pooled.shape[-1] - self.drop
        if kept < 1:
            raise ValueError(f"the target drops {self.drop} of {pooled.shape[-1]} atoms: none left")
        atoms = torch.sort(pooled, dim=-1).values[..., :kept]
        return atoms - self.alpha * log_prob.unsqueeze(-1)

    def critic_error(self, values: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """The quantile Huber loss of each critic's atoms against every kept target atom
        (``quantile_huber_loss``), summed over critics, averaged over the minibatch."""
        return quantile_huber_loss(values, target)

    def actor_value(self, values: torch.Tensor) -> torch.Tensor:
        """The mean of every critic's atoms, ``[batch]`` (the policy gradient reads the whole mixture)."""
        return values.mean(dim=(0, -1))


def quantile_huber_loss(atoms: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """sum over critics c, atoms i, targets j of |tau_i - 1{t_j < a_ci}| huber(t_j - a_ci), over batch x
    atoms x targets: TorchRL's (and sb3-contrib's) TQC critic loss for atoms ``[critics, batch, n]``
    (tau_i = (i + 1/2) / n) and target atoms ``[batch, kept]`` (no gradient).

    Computed without the ``[critics, batch, n, kept]`` tensor of pairs those build (at 25 atoms, 2
    critics and 46 kept targets about half a million entries, a dozen passes over it forward and
    back: a fifth of a CPU step). Against sorted targets, the pairs an atom a forms fall in four runs:
    t < a - 1 and t > a + 1, where the Huber loss is linear (|t - a| - 1/2), and the two runs within 1
    of a, where it is quadratic ((t - a)^2 / 2); each run's sum is a polynomial in a of the run's count,
    sum and sum of squares, read from prefix sums at the run's ends (found by binary search). The sums
    are in float64: the quadratic runs subtract prefix sums of squares."""
    critics, batch, n = atoms.shape
    kept = target.shape[-1]
    t = target.detach().sort(dim=-1).values
    a32 = atoms.transpose(0, 1).reshape(batch, critics * n)  # each row: its transition's atoms
    bounds = a32.detach()
    cuts = torch.searchsorted(t, torch.cat([bounds - 1.0, bounds, bounds + 1.0], dim=-1)).chunk(3, -1)
    t = t.double()
    zero = t.new_zeros(batch, 1)
    prefix = [torch.cat([zero, t.cumsum(-1)], -1), torch.cat([zero, t.square().cumsum(-1)], -1)]
    # (count, sum, sum of squares) of the targets below each cut: below a - 1, below a, below a + 1
    below = [(cut.double(), prefix[0].gather(-1, cut), prefix[1].gather(-1, cut)) for cut in cuts]
    everything = (float(kept), prefix[0][:, -1:], prefix[1][:, -1:])
    a = a32.double()

    def run(lo: tuple, hi: tuple, quadratic: bool, sign: float) -> torch.Tensor:
        """The Huber losses of an atom against the targets between two cuts: linear runs
        sign x (sum of t - count x a) - count / 2 (sign -1 below the atom), quadratic ones halved squares."""
        count, total, squares = (h - lo_ for h, lo_ in zip(hi, lo, strict=True))
        if quadratic:
            return 0.5 * (squares - 2.0 * a * total + count * a.square())
        return sign * (total - count * a) - 0.5 * count

    none = (0.0, 0.0, 0.0)
    under = run(none, below[0], False, -1.0) + run(below[0], below[1], True, -1.0)
    over = run(below[1], below[2], True, 1.0) + run(below[2], everything, False, 1.0)
    tau = ((torch.arange(n, device=a.device, dtype=a.dtype) + 0.5) / n).repeat(critics)
    total = ((1.0 - tau) * under + tau * over).sum() / (batch * n * kept)
    return total.to(atoms.dtype)
