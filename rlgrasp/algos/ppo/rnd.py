"""Random Network Distillation (Burda et al. 2018): curiosity as an intrinsic reward for PPO.

The intrinsic reward of a transition is the error of a trained predictor against a fixed random
network on its next observation (whitened by running statistics and clipped to [-5, 5]): large on
states seldom seen, shrinking as the predictor learns them. As in the reference, it is divided by
the running standard deviation of the intrinsic *returns* (each env's discounted sum of the errors,
kept across batches and episode ends), not of the per-step errors: those vary far less than the
returns, and dividing by their spread made the intrinsic value targets tens to hundreds of times
larger than the extrinsic ones, so the intrinsic value loss ruled the shared gradient clip and the
actor stopped learning. It has its own value head and its own non-episodic returns (an episode's end
is no reason for novelty to stop paying), and ``algo.terms.rnd.coeff`` times its advantage is added to
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

from rlgrasp.models.mlp import OBS_KEY, RunningNorm

INTRINSIC_REWARD = "intrinsic_reward"
INTRINSIC_TARGET = "intrinsic_value_target"
OBS_CLIP = 5.0


def _net(obs_dim: int, out: int) -> MLP:
    return MLP(in_features=obs_dim, out_features=out, num_cells=[256, 256], activation_class=nn.ELU)


class RND(nn.Module):
    """The random target, its predictor, their statistics and the intrinsic value head; the
    ``PPOLearner`` auxiliary-term interface (``start``, ``after_gae``, ``loss``)."""

    def __init__(self, obs_dim: int, norm: RunningNorm, term: Any, ppo_loss: Any):
        """``term``: ``algo.terms.rnd``; ``ppo_loss``: ``algo.loss`` (its GAE lambda and critic weight
        serve the intrinsic value too)."""
        super().__init__()
        self.target, self.predictor = _net(obs_dim, term.features), _net(obs_dim, term.features)
        self.target.requires_grad_(False)
        self.obs_rms = RunningMeanStd((obs_dim,))
        self.reward_rms = RunningMeanStd(())  # of the intrinsic returns
        self.register_buffer("running_return", torch.zeros(0))  # per env; sized by the first batch
        self.value = _net(obs_dim, 1)  # reads PPO's normalized observation
        self.norm = [norm]  # a list: the normalizer is the actor's, not this module's state
        self.predictor_loss = RNDLoss(
            self.predictor,
            self.target,
            obs_rms=self.obs_rms,
            obs_clip=OBS_CLIP,
            update_fraction=term.update_fraction,
        )
        self.term, self.ppo_loss = term, ppo_loss

    @classmethod
    def from_config(cls, term: Any, algorithm: Any) -> RND | None:
        """The curiosity of ``algorithm`` (on its state observation); None at coeff 0."""
        if not term.coeff:
            return None
        spec, loss = algorithm.parts.spec, algorithm.cfg.algo.loss
        return cls(spec["obs_dim"], algorithm.parts.norm, term, loss).to(algorithm.device)

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
        self.reward_rms.update(self._running_returns(raw))
        reward = raw / self.reward_rms.var.clamp_min(1e-8).sqrt()
        batch[INTRINSIC_REWARD] = reward.unsqueeze(-1)
        return {"charts/intrinsic_reward": float(reward.mean()), "charts/intrinsic_error": float(raw.mean())}

    def _running_returns(self, raw: torch.Tensor) -> torch.Tensor:
        """Each env's discounted sum of errors at each step of a ``[envs, time]`` batch, carried
        over from the last batch (CleanRL's ``RewardForwardFilter``; TorchRL has none)."""
        if self.running_return.shape != raw.shape[:-1]:
            self.running_return = raw.new_zeros(raw.shape[:-1])
        returns = torch.empty_like(raw)
        running = self.running_return
        for t in range(raw.shape[-1]):
            running = running * self.term.gamma + raw[..., t]
            returns[..., t] = running
        self.running_return = running
        return returns

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs) -> None:
        key = prefix + "running_return"
        # its size is the saving run's number of envs, unknown to a fresh module
        self.running_return = state_dict.setdefault(key, torch.zeros(0)).clone()
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def _value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.value(self.norm[0](obs))

    @torch.no_grad()
    def after_gae(self, batch: TensorDictBase) -> None:
        """Add ``coeff`` x the intrinsic advantage (no episode ends) to PPO's."""
        reward = batch[INTRINSIC_REWARD]
        never = torch.zeros_like(reward, dtype=torch.bool)
        adv, target = generalized_advantage_estimate(
            self.term.gamma,
            self.ppo_loss.gae_lambda,
            self._value(batch[OBS_KEY]),
            self._value(batch["next", OBS_KEY]),
            reward,
            never,
            never,
        )
        batch["advantage"] = batch["advantage"] + self.term.coeff * adv
        batch[INTRINSIC_TARGET] = target

    def loss(self, minibatch: TensorDictBase) -> tuple[torch.Tensor, dict[str, float]]:
        value_loss = nn.functional.mse_loss(self._value(minibatch[OBS_KEY]), minibatch[INTRINSIC_TARGET])
        predictor = self.predictor_loss(minibatch)["loss_predictor"]
        total = self.ppo_loss.critic_coeff * value_loss + predictor
        values = {"intrinsic_value_loss": float(value_loss.detach()), "rnd_loss": float(predictor.detach())}
        return total, values
