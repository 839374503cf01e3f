"""The PPO update: GAE (each epoch by default), clipped loss over shuffled minibatches.

TorchRL provides the pieces (``GAE``, ``ClipPPOLoss``, ``SamplerWithoutReplacement``); this module
only adds what it lacks: the learning-rate schedule (linear, or KL-adaptive), the target-KL stop,
finiteness checks, the per-update metrics, the refreshed log-probs of stale batches, and auxiliary
terms (``extras``: the imitation term of ``rlgrasp.demos.bc``, the curiosity of ``rlgrasp.algos.ppo.rnd``).

Stale batches (collected with the weights of one update before, ``collector.overlap``): their
log-probs are recomputed with the learner's weights before the epochs, so the clip and the
target-KL stop act around this update's starting policy, as with fresh batches; the one update of
lag between the collecting policy and that one is not corrected. With the log-probs recorded at
collection the KL would start at the last update's and the target-KL stop would cut the epochs
short; TorchRL's decoupled loss (``delay_actor``, the collecting policy's ratio kept as a weight)
lets the k1 KL estimate go negative, so the stop never fires. What each choice does to learning:
docs/benchmarks/throughput.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import torch
from tensordict import TensorDictBase
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from rlgrasp.models.mlp import OBS_KEY, RunningNorm
from rlgrasp.train.algorithm import NonFiniteError

__all__ = ["NonFiniteError", "PPOLearner", "explained_variance"]

#: Bounds of the KL-adaptive learning rate (``algo.schedule.desired_kl``), rsl_rl's.
ADAPTIVE_LR_RANGE = (1e-5, 1e-2)
#: The importance ratio pi_new / pi_old is capped at exp(LOG_RATIO_BOUND). A saturated tanh action
#: with the standard deviation at its floor can have log-probs thousands apart under two nearby
#: policies: exp of that is inf, the loss inf or NaN, and training stops (PPO from pixels did, on
#: all three seeds). An ordinary update's ratio stays within a few times 1 +- clip_epsilon, so it
#: never reaches the cap and trains bit for bit as without it.
LOG_RATIO_BOUND = 20.0


class Extra(Protocol):
    """An auxiliary term of the PPO update: ``start`` once per update (its metrics are logged as
    named), ``after_gae`` after each advantage pass, ``loss`` added to each minibatch's loss."""

    def trainable(self) -> list[torch.nn.Parameter]: ...
    def start(self, batch: TensorDictBase, updates: int) -> dict[str, float]: ...
    def after_gae(self, batch: TensorDictBase) -> None: ...
    def loss(self, minibatch: TensorDictBase) -> tuple[torch.Tensor, dict[str, float]]: ...


class PPOLearner:
    """Owns the loss, the advantage estimator and the optimizer; ``update`` does one PPO round."""

    def __init__(
        self,
        actor,
        critic,
        norm: RunningNorm | Mapping[str, RunningNorm],
        algo_cfg: Any,
        device: torch.device,
        stale_batches: bool = False,
        extras: Sequence[Extra] = (),
    ):
        """``norm``: the normalizer of ``observation``, or each normalizer by the batch entry it learns
        from (a camera run's actor and critic read different entries, each through its own)."""
        self.cfg = algo_cfg
        self.norms = dict(norm) if isinstance(norm, Mapping) else {OBS_KEY: norm}
        self.device = device
        self.loss = ClipPPOLoss(
            actor,
            critic,
            clip_epsilon=algo_cfg.loss.clip_epsilon,
            entropy_bonus=True,
            entropy_coeff=algo_cfg.loss.entropy_coeff,
            critic_coeff=algo_cfg.loss.critic_coeff,
            loss_critic_type=algo_cfg.loss.loss_critic_type,
            normalize_advantage=algo_cfg.loss.normalize_advantage,
            # TorchRL's own cap: it lifts the (gradient-free) old log-prob rather than clamping the
            # ratio, so a capped sample keeps a finite, rescaled gradient instead of none.
            max_importance_ratio=math.exp(LOG_RATIO_BOUND),
        )
        self.actor = actor
        self.stale_batches = stale_batches
        self.gae = GAE(
            gamma=algo_cfg.loss.gamma, lmbda=algo_cfg.loss.gae_lambda, value_network=critic, average_gae=False
        )
        self.extras = list(extras)
        self.params = [*self.loss.parameters(), *(p for x in self.extras for p in x.trainable())]
        self.optimizer = torch.optim.Adam(self.params, lr=algo_cfg.optim.lr, eps=algo_cfg.optim.adam_eps)
        #: The actor's PPO terms are left out of the loss (``algo.schedule.critic_warmup_frames``).
        self.actor_frozen = False

    def lr_at(self, frames: int, total_frames: int) -> float:
        """Linear annealing by frames (so a resumed run continues the same schedule), over
        ``algo.schedule.anneal_lr_frames`` when set, else ``total_frames``; with
        ``algo.schedule.desired_kl``, the rate the KL left (kept in Adam's state, so a resumed run
        continues from it too)."""
        schedule, lr = self.cfg.schedule, self.cfg.optim.lr
        if schedule.desired_kl is not None:
            return self.optimizer.param_groups[0]["lr"]
        horizon = schedule.anneal_lr_frames or total_frames
        if not schedule.anneal_lr or horizon <= 0:
            return lr
        return lr * max(schedule.min_lr_frac, 1.0 - frames / horizon)

    def set_lr(self, lr: float) -> None:
        for group in self.optimizer.param_groups:
            group["lr"] = lr

    def adapt_lr(self, kl: float) -> None:
        """rsl_rl's adaptive schedule, one minibatch's KL at a time (torch's and TorchRL's schedulers
        follow steps or a metric's plateau, none a KL target)."""
        target, lr = self.cfg.schedule.desired_kl, self.optimizer.param_groups[0]["lr"]
        if kl > 2.0 * target:
            self.set_lr(max(ADAPTIVE_LR_RANGE[0], lr / 1.5))
        elif kl < 0.5 * target:
            self.set_lr(min(ADAPTIVE_LR_RANGE[1], lr * 1.5))

    def update(self, batch: TensorDictBase, updates: int = 0) -> dict[str, float]:
        """One PPO round on a ``[envs, time]`` batch (``updates``: how many came before); returns
        averaged metrics."""
        optim, schedule = self.cfg.optim, self.cfg.schedule
        batch = batch.to(self.device)
        n = batch.numel()
        mb = min(optim.minibatch_size, n)
        buffer = self._buffer(n, mb)
        if self.stale_batches:
            self.refresh_log_probs(batch)
        started = {k: v for x in self.extras for k, v in x.start(batch, updates).items()}
        sums: dict[str, float] = {}
        count = 0
        stopped_early = False
        for epoch in range(optim.epochs):
            if epoch == 0 or self.cfg.loss.gae_every_epoch:
                with torch.no_grad():
                    self.gae(batch)
                    for extra in self.extras:
                        extra.after_gae(batch)
                buffer.empty()
                buffer.extend(batch.reshape(-1))
            for _ in range(n // mb):
                sums["lr"] = sums.get("lr", 0.0) + self.optimizer.param_groups[0]["lr"]
                kl = self._minibatch_step(buffer.sample(), sums)
                count += 1
                if schedule.desired_kl is not None and not self.actor_frozen:  # frozen: no KL to follow
                    self.adapt_lr(kl)
                if schedule.target_kl is not None and kl > schedule.target_kl:
                    stopped_early = True
                    break
            if stopped_early:
                break
        self.check_params()
        # The statistics move only after the update: the batch's log-probs were computed with the
        # old ones, and updating first would make the ratio differ from 1 before any step is taken.
        for key, norm in self.norms.items():
            norm.update(batch[key])
        metrics = {**started, **{k: v / max(count, 1) for k, v in sums.items()}}
        # The rate the minibatches stepped at, on average: the KL-adaptive one moves within an update.
        metrics["charts/learning_rate"] = metrics.pop("lr", self.optimizer.param_groups[0]["lr"])
        metrics["explained_variance"] = explained_variance(batch)
        metrics["epochs"] = float(epoch + 1)
        metrics["minibatches"] = float(count)
        return metrics

    def _minibatch_step(self, minibatch: TensorDictBase, sums: dict[str, float]) -> float:
        """One gradient step (PPO's losses and the extras' terms); adds its metrics to ``sums`` and
        returns the minibatch's KL estimate (for the early stop)."""
        losses = self.loss(minibatch)
        total = losses["loss_critic"]
        if not self.actor_frozen:
            total = total + losses["loss_objective"] + losses["loss_entropy"]
        for extra in self.extras:
            term, values = extra.loss(minibatch)
            total = total + term
            for key, value in values.items():
                sums[key] = sums.get(key, 0.0) + value
        if not torch.isfinite(total):
            raise NonFiniteError(
                "non-finite PPO loss "
                + ", ".join(f"{k}={float(v):.4g}" for k, v in losses.items() if v.numel() == 1)
            )
        self.optimizer.zero_grad(set_to_none=True)
        total.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(self.params, self.cfg.optim.max_grad_norm)
        if not torch.isfinite(grad_norm):
            raise NonFiniteError(f"non-finite gradient norm {float(grad_norm)}")
        self.optimizer.step()
        for key, value in (
            ("policy_loss", losses["loss_objective"]),
            ("value_loss", losses["loss_critic"]),
            ("entropy", losses["entropy"]),
            ("approx_kl", losses["kl_approx"]),
            ("clipfrac", losses["clip_fraction"]),
            ("grad_norm", grad_norm),
        ):
            sums[key] = sums.get(key, 0.0) + float(value.detach())
        return float(losses["kl_approx"])

    @torch.no_grad()
    def refresh_log_probs(self, batch: TensorDictBase) -> None:
        """The batch's log-probs under the current weights (see the module docstring)."""
        key = self.loss.tensor_keys.sample_log_prob
        old = batch[key]
        batch[key] = self.actor.get_dist(batch).log_prob(batch["action"]).reshape(old.shape).to(old.dtype)

    def _buffer(self, n: int, mb: int) -> ReplayBuffer:
        """One buffer reused across updates (same batch size every round)."""
        if getattr(self, "_rb_shape", None) != (n, mb):
            self._rb = ReplayBuffer(
                storage=LazyTensorStorage(n, device=self.device),
                sampler=SamplerWithoutReplacement(drop_last=True),
                batch_size=mb,
            )
            self._rb_shape = (n, mb)
        return self._rb

    def check_params(self) -> None:
        for p in self.params:
            if not torch.isfinite(p).all():
                raise NonFiniteError("non-finite values in the network parameters")


def explained_variance(batch: TensorDictBase) -> float:
    """1 - Var(returns - values) / Var(returns), from the last GAE pass."""
    target = batch["value_target"].flatten()
    value = batch["state_value"].flatten()
    var = target.var()
    if var.item() == 0 or math.isnan(var.item()):
        return float("nan")
    return float(1.0 - (target - value).var() / var)
