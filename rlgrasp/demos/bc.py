"""Learning from demonstrations: behaviour-cloning pre-training, and DAPG's imitation term in PPO.

Both regress the actor's deterministic action onto the demonstrated one with TorchRL's ``BCLoss``
(mean squared error, as the camera student of ``rlgrasp.algos.dagger``): the expert's gripper
command is exactly +-1, where the squashed Gaussian's log-likelihood is unbounded. Pre-training
also fits the critic to the demonstrations' discounted returns, so the first advantages are not
computed against a random value. The imitation term is weighted ``coeff * decay ** k`` at update
``k`` (``algo.terms.imitation``) (Rajeswaran et al. 2018, "Learning Complex Dexterous Manipulation with Deep
Reinforcement Learning and Demonstrations"): it holds the policy near the expert while PPO's own
advantages are still noise, then fades.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torch import nn
from torchrl.data import LazyTensorStorage, RandomSampler, ReplayBuffer, SamplerWithoutReplacement
from torchrl.envs import ExplorationType, set_exploration_type
from torchrl.objectives import BCLoss

from rlgrasp.demos.dataset import Demos
from rlgrasp.models.mlp import OBS_KEY, RunningNorm

VALUE_TARGET = "value_target"


def mse_bc_loss(actor: nn.Module) -> BCLoss:
    """TorchRL's behaviour-cloning loss (MSE to the labelled actions), built without the
    ``UserWarning`` TorchRL 0.14 prints on every construction about its own internal
    ``target_actor_network_params`` attribute: nothing a user can act on."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The name target_actor_network_params")
        return BCLoss(actor, loss_function="mse")


def successful(demos: Demos, gamma: float) -> TensorDict:
    """The transitions of successful episodes, with their discounted returns as value targets."""
    frames = demos.frames.clone()
    frames[VALUE_TARGET] = demos.returns(gamma).unsqueeze(-1)
    return frames[frames["success"]].select(OBS_KEY, "action", VALUE_TARGET)


def decayed_weight(term: Any, updates: int) -> float:
    """A term's weight at update ``k``: ``coeff * decay ** k`` (DAPG's ``lambda0 * lambda1 ** k``)."""
    return float(term.coeff * term.decay**updates)


def pretrain(
    actor: nn.Module, critic: nn.Module, norm: RunningNorm, demos: Demos, pretrain_cfg: Any, gamma: float
) -> dict[str, float]:
    """``pretrain_cfg.epochs`` epochs of behaviour cloning (actor) and return regression (critic) on
    the successful demonstrations (returns discounted by ``gamma``); returns the first and last
    epochs' mean losses."""
    data = successful(demos, gamma)
    norm.update(data[OBS_KEY])  # PPO's updates continue these statistics
    mb = min(pretrain_cfg.minibatch_size, data.numel())
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(data.numel()), sampler=SamplerWithoutReplacement(), batch_size=mb
    )
    buffer.extend(data)
    bc = mse_bc_loss(actor)
    params = list({id(p): p for p in [*actor.parameters(), *critic.parameters()]}.values())
    optimizer = torch.optim.Adam(params, lr=pretrain_cfg.lr)
    epochs: list[tuple[float, float]] = []
    for _ in range(pretrain_cfg.epochs):
        sums = [0.0, 0.0]
        steps = math.ceil(data.numel() / mb)
        for _ in range(steps):
            batch = buffer.sample()
            with set_exploration_type(ExplorationType.DETERMINISTIC):
                loss_bc = bc(batch)["loss_bc"]
            value = critic(batch.select(OBS_KEY))["state_value"]
            loss_v = nn.functional.mse_loss(value, batch[VALUE_TARGET])
            optimizer.zero_grad(set_to_none=True)
            (loss_bc + loss_v).backward()
            optimizer.step()
            sums[0] += float(loss_bc.detach())
            sums[1] += float(loss_v.detach())
        epochs.append((sums[0] / steps, sums[1] / steps))
    if not epochs:
        return {}
    return {
        "pretrain/bc_loss_first": epochs[0][0],
        "pretrain/bc_loss_last": epochs[-1][0],
        "pretrain/value_loss_first": epochs[0][1],
        "pretrain/value_loss_last": epochs[-1][1],
        "pretrain/frames": float(data.numel()),
    }


class Imitation:
    """DAPG's auxiliary term for ``PPOLearner`` (``algo.terms.imitation``): a weighted BC loss on a
    demonstration minibatch beside each PPO minibatch."""

    def __init__(self, actor: nn.Module, demos: Demos, term: Any, device: torch.device):
        data = successful(demos, gamma=1.0).select(OBS_KEY, "action")  # the returns are not used
        self.buffer = ReplayBuffer(
            storage=LazyTensorStorage(data.numel(), device=device),
            sampler=RandomSampler(),
            batch_size=min(term.minibatch_size, data.numel()),
        )
        self.buffer.extend(data)
        self.loss_fn = mse_bc_loss(actor)
        self.term = term
        self.weight = decayed_weight(term, 0)

    @classmethod
    def from_config(cls, term: Any, algorithm: Any) -> Imitation | None:
        """The term of ``algorithm`` (its actor and ``demos``); None without demonstrations or at
        coeff 0."""
        if algorithm.demos is None or term.coeff <= 0:
            return None
        return cls(algorithm.actor, algorithm.demos, term, algorithm.device)

    def trainable(self) -> list[nn.Parameter]:
        return []  # the actor's, which the PPO optimizer already holds

    def start(self, batch: TensorDictBase, updates: int) -> dict[str, float]:
        self.weight = decayed_weight(self.term, updates)
        return {"charts/demo_weight": self.weight}

    def after_gae(self, batch: TensorDictBase) -> None:
        pass

    def loss(self, minibatch: TensorDictBase) -> tuple[torch.Tensor, dict[str, float]]:
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            bc = self.loss_fn(self.buffer.sample())["loss_bc"]
        return self.weight * bc, {"bc_loss": float(bc.detach())}
