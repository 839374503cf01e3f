"""An auxiliary task for a camera learner: from its image features alone, say where the object is.

Regressing actions onto a teacher's labels trains the image encoder only through the action error,
a weak and late signal of what in the image matters; a critic that reads the privileged state
(SAC's asymmetric critics) needs little from the images at all. The privileged state holds the
answer the encoder must find (the object's offset from the grasp point, whether it is held), so
during training a linear head reads the encoder's features and is regressed onto those parts,
standardized. With a camera that reports ``object_cells`` (``rlgrasp.envs.cameras.CameraSpec``),
the part can also be where in the image the object lies, a k x k map of its pixels: a label in the
camera's own frame, on every texture the visuals draw. The head is the learner's, not the
policy's: nothing of it is deployed or exported, and the policy's observation stays
proprioception and images.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch
from tensordict import TensorDictBase
from torch import nn

from rlgrasp.config import ConfigError
from rlgrasp.models.mlp import RunningNorm
from rlgrasp.models.spec import PRIVILEGED_KEY


class FeatureTap:
    """A forward hook keeping a module's last output (a class, not a closure: the student is
    pickled into the collector's workers, hooks and all)."""

    def __init__(self) -> None:
        self.output: torch.Tensor | None = None

    def __call__(self, _module: nn.Module, _inputs: tuple, output: torch.Tensor) -> None:
        self.output = output


class ObjectFromImages(nn.Module):
    """A linear head on the student's image features predicting named parts of ``privileged``.

    The features are tapped from the student's encoders as the action loss runs the student, so
    the auxiliary loss costs one small matrix product, not a second encoder pass."""

    def __init__(
        self,
        encoders: Mapping[str, nn.Module],
        parts: Mapping[str, Sequence[int]],
        names: Sequence[str],
        tap: bool = True,
    ) -> None:
        super().__init__()
        unknown = [n for n in names if n not in parts]
        if unknown or not names:
            cells = "object_cells" in unknown
            hint = " (the camera reports them with +env.camera.object_cells=8)" if cells else ""
            raise ConfigError(
                f"algo.terms.aux.parts: unknown part {(unknown or [None])[0]!r}; parts of the privileged "
                f"state: {', '.join(parts)}{hint}"
            )
        self.index = torch.cat([torch.arange(*parts[n]) for n in names])
        features = sum(e.project[0].out_features for e in encoders.values())
        self.head = nn.Linear(features, int(self.index.numel()))
        self.norm = RunningNorm(int(self.index.numel()))
        self.taps = [FeatureTap() for _ in encoders] if tap else []  # tap=False: loss_of only
        for encoder, hook in zip(encoders.values(), self.taps):
            encoder.register_forward_hook(hook)

    def update(self, batch: TensorDictBase) -> None:
        """Fold a batch's targets into the standardization statistics."""
        self.norm.update(batch[PRIVILEGED_KEY][..., self.index])

    def loss(self, minibatch: TensorDictBase) -> torch.Tensor:
        """Mean squared error of the standardized targets, from the features of the last forward."""
        return self.loss_of(torch.cat([tap.output for tap in self.taps], -1), minibatch)

    def loss_of(self, features: torch.Tensor, minibatch: TensorDictBase) -> torch.Tensor:
        """Mean squared error of the standardized targets, from these features (a learner that
        encodes the minibatch itself, as SAC does, passes them)."""
        target = self.norm(minibatch[PRIVILEGED_KEY][..., self.index])
        return (self.head(features) - target).pow(2).mean()
