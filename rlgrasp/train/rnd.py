"""Random Network Distillation (Burda et al. 2018): curiosity as an intrinsic reward for PPO.

The intrinsic reward of a transition is the error of a trained predictor against a fixed random
network on its next observation (whitened by running statistics and clipped to [-5, 5]), divided by
the running standard deviation of those rewards: large on states seldom seen, shrinking as the
predictor learns them. It has its own value head and its own non-episodic returns (an episode's end
is no reason for novelty to stop paying), and ``algo.rnd_coeff`` times its advantage is added to
PPO's. TorchRL provides the predictor's loss (``RNDLoss``) and the running statistics
(``RunningMeanStd``); its ``RNDTransform`` computes the reward inside the env, which here runs in
the collector's workers while the predictor trains in the learner, so the reward is computed in the
learner on each batch instead.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs.transforms.rnd import RunningMeanStd
from torchrl.modules import MLP
from torchrl.objectives.rnd import RNDLoss
from torchrl.objectives.value.functional import generalized_advantage_estimate

from rlgrasp.train.models import OBS_KEY, RunningNorm

INTRINSIC_REWARD = "intrinsic_reward"
INTRINSIC_TARGET = "intrinsic_value_target"
OBS_CLIP = 5.0


def _net(obs_dim: int, out: int) -> MLP:
    return MLP(in_features=obs_dim, out_features=out, num_cells=[256, 256], activation_class=nn.ELU)


class RND(nn.Module):
    """The random target, its predictor, their statistics and the intrinsic value head; the
    ``PPOLearner`` auxiliary-term interface (``start``, ``after_gae``, ``loss``)."""

    def __init__(self, obs_dim: int, norm: RunningNorm, algo: Any):
        super().__init__()
        self.target, self.predictor = _net(obs_dim, algo.rnd_features), _net(obs_dim, algo.rnd_features)
        self.target.requires_grad_(False)
        self.obs_rms = RunningMeanStd((obs_dim,))
        self.reward_rms = RunningMeanStd(())
        self.value = _net(obs_dim, 1)  # reads PPO's normalized observation
        self.norm = [norm]  # a list: the normalizer is the actor's, not this module's state
        self.predictor_loss = RNDLoss(
            self.predictor, self.target, obs_rms=self.obs_rms, obs_clip=OBS_CLIP,
            update_fraction=algo.rnd_update_fraction,
        )
        self.algo = algo

    def trainable(self) -> list[nn.Parameter]:
        return [*self.predictor.parameters(), *self.value.parameters()]

    @torch.no_grad()
    def novelty(self, obs: torch.Tensor) -> torch.Tensor:
        """The predictor's squared error per observation (before the reward's normalization)."""
        x = self.obs_rms.normalize(obs).clamp(-OBS_CLIP, OBS_CLIP)
        return (self.predictor(x) - self.target(x)).pow(2).mean(-1)

    def start(self, batch: TensorDictBase, updates: int) -> dict[str, float]:
        """The batch's intrinsic rewards (statistics updated first, as in the reference)."""
        next_obs = batch["next", OBS_KEY]
        self.obs_rms.update(next_obs)
        raw = self.novelty(next_obs)
        self.reward_rms.update(raw)
        reward = raw / self.reward_rms.var.clamp_min(1e-8).sqrt()
        batch[INTRINSIC_REWARD] = reward.unsqueeze(-1)
        return {"charts/intrinsic_reward": float(reward.mean()), "charts/intrinsic_error": float(raw.mean())}

    def _value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.value(self.norm[0](obs))

    @torch.no_grad()
    def after_gae(self, batch: TensorDictBase) -> None:
        """Add ``rnd_coeff`` x the intrinsic advantage (no episode ends) to PPO's."""
        reward = batch[INTRINSIC_REWARD]
        never = torch.zeros_like(reward, dtype=torch.bool)
        adv, target = generalized_advantage_estimate(
            self.algo.rnd_gamma, self.algo.gae_lambda, self._value(batch[OBS_KEY]),
            self._value(batch["next", OBS_KEY]), reward, never, never,
        )
        batch["advantage"] = batch["advantage"] + self.algo.rnd_coeff * adv
        batch[INTRINSIC_TARGET] = target

    def loss(self, minibatch: TensorDictBase) -> tuple[torch.Tensor, dict[str, float]]:
        value_loss = nn.functional.mse_loss(self._value(minibatch[OBS_KEY]), minibatch[INTRINSIC_TARGET])
        predictor = self.predictor_loss(minibatch)["loss_predictor"]
        total = self.algo.critic_coeff * value_loss + predictor
        values = {"intrinsic_value_loss": float(value_loss.detach()), "rnd_loss": float(predictor.detach())}
        return total, values
