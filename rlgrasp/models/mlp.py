"""Actor and critic builders: MLPs behind a shared observation normalizer."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch
from tensordict.nn import (
    AddStateIndependentNormalScale,
    InteractionType,
    TensorDictModule,
)
from torch import nn
from torchrl.modules import MLP, IndependentNormal, ProbabilisticActor, TanhNormal, ValueOperator


@dataclass
class MLPConfig:
    """Actor and critic MLPs; the observation normalizer sits inside both."""

    name: str = "mlp"
    hidden_sizes: list[int] = field(default_factory=lambda: [256, 256, 256])
    activation: str = "tanh"  # tanh | relu | elu
    init_log_std: float = -0.5
    # Floor of the state-independent std: keeps long runs from collapsing exploration.
    min_std: float = 0.05
    obs_norm: bool = True
    obs_clip: float = 10.0
    # tanh_normal: a Gaussian squashed into the action bounds; normal: the Gaussian, the env clipping
    # what it executes (Stable-Baselines3's and CleanRL's policy). docs/benchmarks/learning.md.
    distribution: str = "tanh_normal"


OBS_KEY = "observation"

#: ``model.activation`` -> its torch module class.
ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU}


class RunningNorm(nn.Module):
    """Running mean/std normalizer of observations, living inside the actor and the critic.

    Why not TorchRL's ``VecNorm``: with the process collector every worker would keep its own
    statistics in its own process, and getting them back into the learner and the checkpoint is
    awkward. Here the statistics are buffers of the policy: the learner updates them from each
    batch, ``update_policy_weights_()`` ships them to the workers with the weights, and they are in
    the checkpoint's state dict, so evaluation from a checkpoint normalizes exactly like training.
    """

    def __init__(self, dim: int, clip: float = 10.0, enabled: bool = True, eps: float = 1e-8) -> None:
        super().__init__()
        self.clip = clip
        self.enabled = enabled
        self.eps = eps
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))

    @torch.no_grad()
    def update(self, obs: torch.Tensor) -> None:
        """Merge a batch's moments into the running ones (Chan et al. parallel algorithm)."""
        if not self.enabled:
            return
        x = obs.reshape(-1, self.mean.shape[-1]).to(torch.float64)
        n = x.shape[0]
        if n == 0:
            return
        b_mean, b_var = x.mean(0), x.var(0, unbiased=False)
        tot = self.count + n
        delta = b_mean - self.mean.double()
        new_mean = self.mean.double() + delta * n / tot
        m2 = self.var.double() * self.count + b_var * n + delta.pow(2) * self.count * n / tot
        self.mean.copy_(new_mean.to(self.mean.dtype))
        self.var.copy_((m2 / tot).to(self.var.dtype))
        self.count.copy_(tot)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if not self.enabled:
            return obs
        out = (obs - self.mean) / torch.sqrt(self.var + self.eps)
        return out.clamp(-self.clip, self.clip)


def _mlp(in_dim: int, out_dim: int, hidden: Sequence[int], activation: str, last_gain: float) -> MLP:
    mlp = MLP(
        in_features=in_dim,
        out_features=out_dim,
        num_cells=list(hidden),
        activation_class=ACTIVATIONS[activation],
    )
    # Orthogonal init as in the PPO reference implementations; a small last layer keeps the
    # initial policy close to zero-mean and the initial values close to zero.
    linears = [m for m in mlp.modules() if isinstance(m, nn.Linear)]
    for i, layer in enumerate(linears):
        gain = last_gain if i == len(linears) - 1 else 2**0.5
        nn.init.orthogonal_(layer.weight, gain=gain)
        nn.init.zeros_(layer.bias)
    return mlp


#: The pre-tanh mean of a squashing actor is clamped to +-LOC_BOUND. Unbounded, a saturated action
#: dimension drifts ever further out, and with the standard deviation at its floor its log-probs
#: reach magnitudes whose differences overflow ``exp`` in the PPO ratio (``rlgrasp.algos.ppo.learner``).
#: At 10 the mode is already at the bound (tanh(10) is 1 in float32, and TorchRL's safe tanh clamps
#: it just below), so the clamp changes no deterministic action; trained policies stay below 5, so
#: an ordinary run never reaches it and trains bit for bit as without it.
LOC_BOUND = 10.0


def bounded_loc(loc: torch.Tensor, squash: bool) -> torch.Tensor:
    """``loc`` clamped to +-``LOC_BOUND`` for a tanh actor; a Gaussian actor's (the env clips its
    action) as it is. A hard clamp rather than TorchRL's ``tanh_loc``: that rescales every loc, so
    ordinary runs would change, and it shifts the loc of asymmetric action bounds."""
    return loc.clamp(-LOC_BOUND, LOC_BOUND) if squash else loc


class ActorNet(nn.Module):
    """normalized obs -> MLP -> (loc, bounded for a tanh actor; state-independent scale)."""

    def __init__(self, norm: RunningNorm, obs_dim: int, act_dim: int, model_cfg) -> None:
        super().__init__()
        self.norm = norm
        self.squash = squashes(model_cfg)
        self.mlp = _mlp(obs_dim, act_dim, model_cfg.hidden_sizes, model_cfg.activation, 0.01)
        self.scale = AddStateIndependentNormalScale(
            act_dim, scale_lb=model_cfg.min_std, init_value=model_cfg.init_log_std
        )

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.scale(bounded_loc(self.mlp(self.norm(obs)), self.squash))


class CriticNet(nn.Module):
    """normalized obs -> MLP -> state value."""

    def __init__(self, norm: RunningNorm, obs_dim: int, model_cfg) -> None:
        super().__init__()
        self.norm = norm
        self.mlp = _mlp(obs_dim, 1, model_cfg.hidden_sizes, model_cfg.activation, 1.0)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.norm(obs))


def build_actor(
    norm: RunningNorm,
    obs_dim: int,
    action_low: torch.Tensor,
    action_high: torch.Tensor,
    model_cfg,
    deterministic: bool = False,
) -> ProbabilisticActor:
    """The policy of ``model.distribution``: ``tanh_normal`` squashes a Gaussian into the action
    bounds (no clipping bias in the log-probs); ``normal`` is the Gaussian itself, as Stable-Baselines3
    and CleanRL use it: the env clips the action it executes, the log-prob is the unclipped sample's.

    ``deterministic=True`` makes the mode of the distribution the default action outside any
    ``set_exploration_type`` context (for evaluation from a checkpoint).
    """
    act_dim = int(action_low.numel())
    net = TensorDictModule(
        ActorNet(norm, obs_dim, act_dim, model_cfg), in_keys=[OBS_KEY], out_keys=["loc", "scale"]
    )
    if squashes(model_cfg):
        low, high = _bound(action_low), _bound(action_high)
        distribution, kwargs = TanhNormal, {"low": low, "high": high, "tanh_loc": False}
    else:
        distribution, kwargs = IndependentNormal, {}
    return ProbabilisticActor(
        net,
        in_keys=["loc", "scale"],
        distribution_class=distribution,
        distribution_kwargs=kwargs,
        return_log_prob=True,
        default_interaction_type=(InteractionType.DETERMINISTIC if deterministic else InteractionType.RANDOM),
    )


def squashes(model_cfg) -> bool:
    """Whether the actor's actions are squashed into the bounds (a model config without the key, as
    in checkpoints written before it existed: yes)."""
    return model_cfg.get("distribution", "tanh_normal") == "tanh_normal"


def _bound(b: torch.Tensor) -> float | torch.Tensor:
    # A scalar bound stays device-agnostic (tensors in distribution_kwargs are not moved by .to()).
    b = torch.as_tensor(b, dtype=torch.float32).flatten()
    return float(b[0]) if bool((b == b[0]).all()) else b


def build_critic(norm: RunningNorm, obs_dim: int, model_cfg, in_key: str = OBS_KEY) -> ValueOperator:
    """A value MLP reading ``in_key`` (a camera run's critic reads ``privileged``, see
    ``rlgrasp.train.parts``)."""
    return ValueOperator(CriticNet(norm, obs_dim, model_cfg), in_keys=[in_key])


def build_models(
    obs_dim: int, action_low: torch.Tensor, action_high: torch.Tensor, model_cfg
) -> tuple[ProbabilisticActor, ValueOperator, RunningNorm]:
    """Actor and critic sharing one normalizer (the actor alone is shipped to the workers)."""
    norm = RunningNorm(obs_dim, clip=model_cfg.obs_clip, enabled=model_cfg.obs_norm)
    actor = build_actor(norm, obs_dim, action_low, action_high, model_cfg)
    critic = build_critic(norm, obs_dim, model_cfg)
    return actor, critic, norm
