"""Policies that see: a small CNN per image, its features joined with the normalized state.

In a TorchRL tensordict the env's ``state`` entry arrives as ``observation`` (TorchRL's gym wrapper
names it so), next to ``depth``/``rgb`` and ``privileged``. The student actor reads ``observation``
and the images; a critic may read ``privileged`` (asymmetric actor-critic: the critic is not
deployed, so it may use what no robot senses).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from tensordict.nn import AddStateIndependentNormalScale, InteractionType, TensorDictModule
from torch import nn
from torchrl.modules import ConvNet, ProbabilisticActor, TanhNormal

from rlgrasp.models.mlp import ACTIVATIONS, OBS_KEY, RunningNorm, _bound, _mlp, bounded_loc

POOLINGS = ("flat", "keypoints")  # how a CNN's last feature maps become features (CNNConfig.pooling)


@dataclass
class CNNConfig:
    """A small CNN per image (by default 8x8/4, 4x4/2, 3x3/1) joined with the normalized state in an MLP."""

    name: str = "cnn"
    channels: list[int] = field(default_factory=lambda: [16, 32, 32])
    kernel_sizes: list[int] = field(default_factory=lambda: [8, 4, 3])
    strides: list[int] = field(default_factory=lambda: [4, 2, 1])
    # flat: the last feature map flattened into the projection; keypoints: each channel's expected
    # image position (x, y) under a softmax over its pixels (rlgrasp/models/cnn.py, SpatialSoftmax)
    pooling: str = "flat"
    image_features: int = 256
    hidden_sizes: list[int] = field(default_factory=lambda: [256, 256])
    activation: str = "elu"  # tanh | relu | elu
    init_log_std: float = -0.5
    min_std: float = 0.05
    obs_norm: bool = True
    obs_clip: float = 10.0


IMAGE_KEYS = ("depth", "rgb")


class SpatialSoftmax(nn.Module):
    """Feature maps (N, C, H, W) -> (N, 2C): each channel's expected (x, y) in [-1, 1] under a softmax
    over its pixels (Levine et al. 2016). Where a thing is, to a fraction of a pixel, from few weights:
    what a grasp needs from an image. Hand-written: TorchRL and torch have no such layer."""

    def __init__(self, height: int, width: int):
        super().__init__()
        ys, xs = torch.meshgrid(torch.linspace(-1, 1, height), torch.linspace(-1, 1, width), indexing="ij")
        self.register_buffer("grid", torch.stack([xs.reshape(-1), ys.reshape(-1)], -1))
        self.log_temperature = nn.Parameter(torch.zeros(()))  # learned: how sharp each channel's peak is

    def forward(self, maps: torch.Tensor) -> torch.Tensor:
        weights = torch.softmax(maps.flatten(2) / self.log_temperature.exp(), dim=-1)
        return (weights @ self.grid).flatten(1)


class ImageEncoder(nn.Module):
    """Image -> feature vector. Depth (metres) is scaled by ``far``; RGB arrives as uint8 and becomes
    float here, so batches and replay data keep images in their compact dtype until the network."""

    def __init__(
        self,
        key: str,
        shape: Sequence[int],
        far: float,
        channels: Sequence[int],
        features: int,
        kernel_sizes: Sequence[int] = (8, 4, 3),
        strides: Sequence[int] = (4, 2, 1),
        pooling: str = "flat",
    ):
        super().__init__()
        self.key, self.far = key, float(far)
        self.conv = ConvNet(
            in_features=shape[0],
            num_cells=list(channels),
            kernel_sizes=list(kernel_sizes),
            strides=list(strides),
            activation_class=nn.ELU,
        )
        if pooling == "keypoints":  # ConvNet flattens its output: keep the maps for the softmax
            self.conv = nn.Sequential(*list(self.conv)[:-1])
            with torch.no_grad():
                height, width = self.conv(torch.zeros(1, *shape)).shape[-2:]
            self.conv.append(SpatialSoftmax(height, width))
        # A one-channel (depth) image goes through channels-last convolutions: on a CPU, PyTorch's
        # default layout took 7x longer for the first layer's weight gradient, and a student's
        # update 2x longer in all. With three channels (RGB) the default layout is the faster one.
        self.layout = torch.channels_last if shape[0] == 1 else torch.contiguous_format
        self.conv.to(memory_format=self.layout)
        with torch.no_grad():
            flat = self.conv(torch.zeros(1, *shape)).shape[-1]
        self.project = nn.Sequential(nn.Linear(flat, features), nn.ELU())

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        x = image.float() / (255.0 if self.key == "rgb" else self.far)
        batch = x.shape[:-3]
        x = x.reshape(-1, *x.shape[-3:]).contiguous(memory_format=self.layout)
        return self.project(self.conv(x)).reshape(*batch, -1)


class VisionActorNet(nn.Module):
    """(normalized state, images) -> MLP -> (loc, state-independent scale). Its state normalizer is
    its own, of ``state_dim`` (``model.obs_clip``, ``model.obs_norm``): the learner finds it with
    ``actor_norm``."""

    def __init__(
        self,
        encoders: Mapping[str, ImageEncoder],
        state_dim: int,
        act_dim: int,
        model_cfg: Any,
    ) -> None:
        super().__init__()
        self.norm = RunningNorm(state_dim, clip=model_cfg.obs_clip, enabled=model_cfg.obs_norm)
        self.encoders = nn.ModuleDict(dict(encoders))
        features = sum(e.project[0].out_features for e in self.encoders.values())
        self.mlp = _mlp(state_dim + features, act_dim, model_cfg.hidden_sizes, model_cfg.activation, 0.01)
        self.scale = AddStateIndependentNormalScale(
            act_dim, scale_lb=model_cfg.min_std, init_value=model_cfg.init_log_std
        )

    def forward(self, state: torch.Tensor, *images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.act(state, self.encode(*images))

    def encode(self, *images: torch.Tensor) -> torch.Tensor:
        """The images' features, joined (one encoder per image, in ``encoders``' order)."""
        return torch.cat([enc(img) for enc, img in zip(self.encoders.values(), images)], -1)

    def act(self, state: torch.Tensor, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(loc, scale) from the state and the images' features."""
        return self.scale(bounded_loc(self.mlp(torch.cat([self.norm(state), features], -1)), squash=True))


class VisionActorHead(nn.Module):
    """The part of a ``VisionActorNet`` after its encoders: (state, image features) -> (loc, scale).

    An off-policy learner from pixels computes the features once per minibatch and chooses which
    loss trains the encoders through them (DrQ-v2, Yarats et al. 2021: the critic's); this head
    holds the actor's own modules (normalizer, MLP, scale), shared with the whole net, which stays
    what acts and is exported."""

    def __init__(self, net: VisionActorNet) -> None:
        super().__init__()
        self.norm, self.mlp, self.scale = net.norm, net.mlp, net.scale
        self._act = VisionActorNet.act

    def forward(self, state: torch.Tensor, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self._act(self, state, features)


def image_specs(spec: Mapping[str, Any]) -> dict[str, tuple[int, ...]]:
    """The image entries of an env spec (``rlgrasp.models.spec.env_spec``): key -> shape."""
    return {k: tuple(spec["images"][k]) for k in IMAGE_KEYS if k in spec.get("images", {})}


def build_vision_actor(
    spec: Mapping[str, Any], model_cfg: Any, deterministic: bool = False
) -> ProbabilisticActor:
    """A TanhNormal actor over the state and the images, shaped by ``spec`` (state ``obs_dim``,
    ``images``, ``far``, action bounds); ``model_cfg`` adds ``channels`` and ``image_features``."""
    images = image_specs(spec)
    if model_cfg.activation not in ACTIVATIONS:
        raise ValueError(
            f"model.activation={model_cfg.activation!r}: must be one of {', '.join(ACTIVATIONS)}"
        )
    # Checkpoints written before kernel_sizes, strides and pooling existed hold the flat encoder.
    conv = dict(
        kernel_sizes=model_cfg.get("kernel_sizes", (8, 4, 3)),
        strides=model_cfg.get("strides", (4, 2, 1)),
        pooling=model_cfg.get("pooling", "flat"),
    )
    if conv["pooling"] not in POOLINGS:
        raise ValueError(f"model.pooling={conv['pooling']!r}: must be one of {', '.join(POOLINGS)}")
    for key in ("kernel_sizes", "strides"):
        if len(conv[key]) != len(model_cfg.channels):
            layers = f"one entry per layer of model.channels={list(model_cfg.channels)}"
            raise ValueError(f"model.{key}={list(conv[key])}: needs {layers}")
    encoders = {
        k: ImageEncoder(k, shape, spec.get("far", 1.0), model_cfg.channels, model_cfg.image_features, **conv)
        for k, shape in images.items()
    }
    low, high = torch.as_tensor(spec["action_low"]), torch.as_tensor(spec["action_high"])
    net = VisionActorNet(encoders, spec["obs_dim"], int(low.numel()), model_cfg)
    module = TensorDictModule(net, in_keys=[OBS_KEY, *images], out_keys=["loc", "scale"])
    return ProbabilisticActor(
        module,
        in_keys=["loc", "scale"],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": _bound(low), "high": _bound(high), "tanh_loc": False},
        return_log_prob=True,
        default_interaction_type=InteractionType.DETERMINISTIC if deterministic else InteractionType.RANDOM,
    )


def vision_net(actor: ProbabilisticActor) -> VisionActorNet:
    """The network inside a vision actor (``build_vision_actor``)."""
    return actor.module[0].module


def head_actor(actor: ProbabilisticActor, features_key: str) -> ProbabilisticActor:
    """``actor``'s TanhNormal policy over (state, ``features_key``) instead of (state, images): the
    same modules after the encoders (``VisionActorHead``), the same distribution."""
    net = vision_net(actor)
    head = VisionActorHead(net)
    module = TensorDictModule(head, in_keys=[OBS_KEY, features_key], out_keys=["loc", "scale"])
    dist = actor.module[-1]  # the ProbabilisticTensorDictModule: its distribution and bounds
    return ProbabilisticActor(
        module,
        in_keys=["loc", "scale"],
        distribution_class=dist.distribution_class,
        distribution_kwargs=dict(dist.distribution_kwargs),
        return_log_prob=True,
        default_interaction_type=InteractionType.RANDOM,
    )


def actor_norm(actor: ProbabilisticActor) -> RunningNorm:
    """The state normalizer inside a vision actor (the learner updates it from each batch)."""
    return vision_net(actor).norm


@torch.no_grad()
def average_weights(average: nn.Module, model: nn.Module, decay: float) -> None:
    """One step of an exponential moving average of ``model``'s parameters into ``average``; buffers
    (the state normalizer's statistics) are copied as they are. Hand-written: torch's
    ``AveragedModel`` wraps the module and renames its state dict, which export and evaluation read."""
    for avg, p in zip(average.parameters(), model.parameters()):
        avg.lerp_(p, 1.0 - decay)
    for avg, b in zip(average.buffers(), model.buffers()):
        avg.copy_(b)


def vision_policy(spec: Mapping[str, Any], model_cfg: Any, weights: Mapping[str, Any]) -> ProbabilisticActor:
    """The deterministic camera policy of a checkpoint's spec, model config and weights."""
    actor = build_vision_actor(spec, model_cfg, deterministic=True)
    actor.load_state_dict(weights)
    return actor.eval()
