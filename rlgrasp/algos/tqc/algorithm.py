"""TQC on the training core: SAC (``rlgrasp.algos.sac``) with quantile critics and TQC's losses
(``rlgrasp.algos.tqc.losses``).

Everything but the losses and the critics' width is SAC's: the update-to-data ratio, the replay and
its files, demonstrations (RLPD), a camera learner's encoders, checkpoints and resume. The loss has
SAC's interface (``critic_loss``, ``actor_loss``, ``alpha_loss``, ``soft_update``, the same parameter
names and target critics), so SAC's step runs it unchanged: each critic outputs ``n_quantiles``
atoms, the target pools every target critic's atoms, drops the top ``top_quantiles_to_drop_per_net``
x ``num_critics`` and regresses each critic onto the rest with the quantile Huber loss; the actor
maximizes the mean of all atoms. Checkpoints written with TorchRL's ``TQCLoss`` load as SAC's do.
"""

from __future__ import annotations

from rlgrasp.algos.sac import SAC
from rlgrasp.algos.tqc.losses import TruncatedQuantileLoss


class TQC(SAC):
    """Truncated quantile critics (``algo=tqc``), optionally with demonstrations (as SAC's RLPD)."""

    name = "tqc"

    @property
    def critic_outputs(self) -> int:
        return int(self.cfg.algo.loss.n_quantiles)

    def _make_loss(self, act_dim: int) -> TruncatedQuantileLoss:
        """TQC's losses (its temperature, target critics and entropy target as SAC's)."""
        loss = self.cfg.algo.loss
        critics, keys = self._critics(act_dim)
        return TruncatedQuantileLoss(
            self._loss_actor(),
            critics,
            keys,
            gamma=loss.gamma,
            alpha_init=loss.alpha_init,
            target_entropy=self._target_entropy(act_dim),
            drop_per_critic=loss.top_quantiles_to_drop_per_net,
        )
