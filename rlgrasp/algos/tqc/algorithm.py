"""TQC on the training core: SAC (``rlgrasp.algos.sac``) with TorchRL's ``TQCLoss``.

Everything but the loss and the critics' width is SAC's: the update-to-data ratio, the replay and
its files, demonstrations (RLPD), a camera learner's encoders, checkpoints and resume. ``TQCLoss``
has ``SACLoss``'s interface (``qvalue_v2_loss``, ``actor_loss``, ``alpha_loss``, the same parameter
names and target critics), so SAC's step runs it unchanged: each critic outputs ``n_quantiles``
atoms, the target pools every target critic's atoms, drops the top ``top_quantiles_to_drop_per_net``
x ``num_critics`` and regresses each critic onto the rest with the quantile Huber loss; the actor
maximizes the mean of all atoms.
"""

from __future__ import annotations

from torchrl.objectives import TQCLoss

from rlgrasp.algos.sac import SAC


class TQC(SAC):
    """Truncated quantile critics (``algo=tqc``), optionally with demonstrations (as SAC's RLPD)."""

    name = "tqc"

    @property
    def critic_outputs(self) -> int:
        return int(self.cfg.algo.loss.n_quantiles)

    def _make_loss(self, act_dim: int) -> TQCLoss:
        """TorchRL's ``TQCLoss`` (its temperature, target critics and entropy target as SAC's)."""
        loss = self.cfg.algo.loss
        return TQCLoss(
            self._loss_actor(),
            self._qvalue(act_dim).to(self.device),
            num_qvalue_nets=loss.num_critics,
            top_quantiles_to_drop_per_net=loss.top_quantiles_to_drop_per_net,
            alpha_init=loss.alpha_init,
            target_entropy=self._target_entropy(act_dim),
            delay_qvalue=True,
        )
