"""The deployable policy: a checkpoint's actor as a plain ``nn.Module``, raw inputs in, action out.

The checkpoint's actor is a TorchRL ``ProbabilisticActor`` reading and writing tensordicts, which no
deployment runtime understands. ``DeployPolicy`` is the same computation (running-mean/std
normalizer -> MLP -> loc -> the TanhNormal's deterministic sample, i.e. a clamped tanh affinely
scaled to the action bounds; or, for a ``model.distribution=normal`` policy, the loc clamped to the
bounds, as the env clips it), built from the very modules the actor holds, so that TorchScript, ONNX
and ``torch.export`` can all serialize it. A camera policy's modules add the image encoders; one
class per modality, because a TorchScript or ONNX signature cannot have optional inputs.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from rlgrasp.models.cnn import ImageEncoder, SpatialSoftmax, image_specs
from rlgrasp.models.mlp import squashes
from rlgrasp.policy_file import policy_from_checkpoint


class DeployPolicy(nn.Module):
    """Raw observation ``[..., obs_dim]`` float32 -> deterministic action ``[..., action_dim]``.

    Matches ``TanhNormal.deterministic_sample`` of the training actor exactly: tanh of the MLP's
    loc clamped to +-(1 - float32 resolution) (TorchRL's safe tanh), then scaled to the bounds.
    ``squash=False`` (a Gaussian policy): the loc clamped to the bounds, the action the env executes.
    """

    def __init__(self, net: nn.Module, low: torch.Tensor, high: torch.Tensor, squash: bool = True) -> None:
        super().__init__()
        self.squash = squash
        norm = net.norm
        self.normalize = bool(norm.enabled)
        self.clip, self.eps = float(norm.clip), float(norm.eps)
        self.register_buffer("mean", norm.mean.detach().clone().float())
        self.register_buffer("var", norm.var.detach().clone().float())
        # A plain Sequential of the same layers (TorchRL's MLP.forward is not scriptable).
        self.mlp = nn.Sequential(*[m for m in net.mlp.children()])
        low, high = torch.as_tensor(low, dtype=torch.float32), torch.as_tensor(high, dtype=torch.float32)
        self.rescale = bool((low != -1).any() or (high != 1).any())
        self.register_buffer("low", low)
        self.register_buffer("high", high)
        self.register_buffer("mid", (high + low) / 2)
        self.register_buffer("half_range", (high - low) / 2)
        self.lim = 1.0 - float(torch.finfo(torch.float32).resolution)

    def normalized(self, x: torch.Tensor) -> torch.Tensor:
        if self.normalize:
            # The same operations in the same order as RunningNorm: bit-identical inputs to the MLP.
            x = ((x - self.mean) / torch.sqrt(self.var + self.eps)).clamp(-self.clip, self.clip)
        return x

    def act(self, x: torch.Tensor) -> torch.Tensor:
        """MLP input -> the deterministic action."""
        if not self.squash:
            return torch.minimum(torch.maximum(self.mlp(x), self.low), self.high)
        y = torch.tanh(self.mlp(x)).clamp(-self.lim, self.lim)
        if self.rescale:
            y = self.mid + self.half_range * y
        return y

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return self.act(self.normalized(observation))


class ImageFeatures(nn.Module):
    """``ImageEncoder`` for one ``[B, C, H, W]`` image: the same layers and scaling (TorchRL's
    ``ConvNet.forward`` and ``SquashDims`` are not scriptable; their layers are)."""

    def __init__(self, encoder: ImageEncoder) -> None:
        super().__init__()
        self.divisor = 255.0 if encoder.key == "rgb" else float(encoder.far)
        layers = (nn.Conv2d, nn.ELU, SpatialSoftmax)
        convs = [m for m in encoder.conv.children() if isinstance(m, layers)]
        self.conv = nn.Sequential(*convs, nn.Flatten(1))  # a no-op after the spatial softmax
        self.project = encoder.project

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.project(self.conv(image.float() / self.divisor))


class _VisionDeploy(DeployPolicy):
    """State (normalized) and image features joined, then the state policy's head."""

    def __init__(self, net: nn.Module, low: torch.Tensor, high: torch.Tensor, squash: bool = True) -> None:
        super().__init__(net, low, high, squash)
        self.encoders = nn.ModuleDict({k: ImageFeatures(e) for k, e in net.encoders.items()})


class DepthPolicy(_VisionDeploy):
    """``observation`` [B, state] float32, ``depth`` [B, 1, H, W] float32 metres -> action."""

    def forward(self, observation: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        features = self.encoders["depth"](depth)
        return self.act(torch.cat([self.normalized(observation), features], -1))


class RGBPolicy(_VisionDeploy):
    """``observation`` [B, state] float32, ``rgb`` [B, 3, H, W] uint8 -> action."""

    def forward(self, observation: torch.Tensor, rgb: torch.Tensor) -> torch.Tensor:
        features = self.encoders["rgb"](rgb)
        return self.act(torch.cat([self.normalized(observation), features], -1))


class RGBDPolicy(_VisionDeploy):
    """``observation``, ``depth`` and ``rgb`` as above -> action (depth features before RGB's, as
    the actor joins them)."""

    def forward(self, observation: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor) -> torch.Tensor:
        state = self.normalized(observation)
        return self.act(torch.cat([state, self.encoders["depth"](depth), self.encoders["rgb"](rgb)], -1))


#: The image entries a camera policy reads -> its deployable class.
VISION_DEPLOY = {("depth",): DepthPolicy, ("rgb",): RGBPolicy, ("depth", "rgb"): RGBDPolicy}


def deploy_module(ckpt: dict[str, Any]) -> DeployPolicy:
    """The deployable module of a loaded checkpoint (a state or a camera policy), built from the
    very modules training uses."""
    actor = policy_from_checkpoint(ckpt, "cpu")
    net = actor.module[0].module
    spec = ckpt["spec"]
    low, high = torch.as_tensor(spec["action_low"]), torch.as_tensor(spec["action_high"])
    images = tuple(image_specs(spec))
    cls = VISION_DEPLOY[images] if images else DeployPolicy
    return cls(net, low, high, squashes(ckpt["config"]["model"])).eval()
