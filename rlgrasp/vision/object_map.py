"""One keypoint of a camera learner's encoder made the object's: its map trained onto the object's pixels.

The keypoint encoder (``model.pooling=keypoints``) ends each image in a spatial softmax: every channel
of its last feature map becomes the expected (x, y) of that channel's activity, and which channel
tracks what is left to the losses. The RGB learner finds a small object on a patterned ground poorly,
on the training textures too (docs/history/algorithms.md, "One keypoint made the object's, and what the
encoder can locate"). This term names one channel, the first, the object's: its map, under a softmax
over its cells, is trained by cross-entropy onto where the object's pixels are (the camera's
``object_cells``, a training label from the simulator's segmentation, resampled onto the cells'
receptive fields). The gradient is dense, one target per map cell, and arrives on every replayed
image, the ground-swapped ones too (``algo.augment.ground_swap``): a detector learned by supervision
rather than through the critics' values. The actor reads that channel's keypoint as it reads every
other; the exported policy is unchanged, and the label is needed in training only. Measured on the
RGB objects experiment: no gain in 30 minutes, and the map located the object only coarsely (the
page above), so it is off unless asked for.

Hand-written: TorchRL has no spatial-softmax encoder, hence no loss on one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from torch import nn

from rlgrasp.config import ConfigError
from rlgrasp.models.cnn import SpatialSoftmax
from rlgrasp.models.spec import PRIVILEGED_KEY


class MapTap:
    """A forward hook keeping the maps a convolution made (a class, not a closure, so that the actor
    it hangs on still pickles)."""

    def __init__(self) -> None:
        self.maps: torch.Tensor | None = None

    def __call__(self, _module: nn.Module, _inputs: tuple, output: torch.Tensor) -> None:
        self.maps = output


def map_window(kernel_sizes: Sequence[int], strides: Sequence[int]) -> tuple[float, int]:
    """Where a map cell sits in the image: the first cell's receptive-field centre (pixels, from the
    image's corner) and the pixels between neighbouring cells (the strides' product)."""
    centre, step = 0.0, 1
    for kernel, stride in zip(kernel_sizes, strides):
        centre += (kernel - 1) / 2 * step
        step *= stride
    return centre, step


def cells_on_map(cells: torch.Tensor, image: int, map_size: int, centre: float, step: int) -> torch.Tensor:
    """``[N, k * k]`` shares of object pixels per cell of a ``k x k`` grid over an ``image``-pixel
    square, as ``[N, map_size * map_size]`` shares per map cell: each map cell averages the
    ``step x step`` pixels around its centre (the grid blown up to pixels, the map's window cut out)."""
    k = math.isqrt(cells.shape[-1])
    pixels = cells.reshape(-1, 1, k, k).repeat_interleave(image // k, -2).repeat_interleave(image // k, -1)
    start = int(round(centre - (step - 1) / 2))
    stop = start + step * map_size
    pad = (max(0, -start), max(0, stop - image))  # a window past the image's edge sees no object there
    pixels = F.pad(pixels, (*pad, *pad))[..., start + pad[0] : stop + pad[0], start + pad[0] : stop + pad[0]]
    return F.avg_pool2d(pixels, step).flatten(1)


def last_conv(encoder: nn.Module) -> nn.Conv2d:
    """An image encoder's last convolution: its output, before the ELU, is the map the term trains."""
    return [m for m in encoder.conv if isinstance(m, nn.Conv2d)][-1]


def map_cross_entropy(
    maps: torch.Tensor, cells: torch.Tensor, image: int, window: tuple[float, int]
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per image: the first map's cross-entropy (softmax over its cells) against the object's pixels
    resampled onto those cells, that target (normalized), and whether the object shows at all."""
    target = cells_on_map(cells, image, maps.shape[-1], *window)
    shows = target.sum(-1) > 0
    target = target / target.sum(-1, keepdim=True).clamp_min(1e-8)
    log_p = torch.log_softmax(maps[:, 0].flatten(1), -1)
    return -(target * log_p).sum(-1), target, shows


class ObjectMap(nn.Module):
    """The cross-entropy between each encoder's first keypoint map (softmax over its cells) and the
    object's pixels resampled onto those cells, on the images that show the object. It owns no weights:
    what it trains are the encoders'."""

    def __init__(
        self,
        encoders: Mapping[str, nn.Module],
        parts: Mapping[str, Sequence[int]],
        image_shapes: Mapping[str, Sequence[int]],
        model_cfg: object,
    ) -> None:
        super().__init__()
        if "object_cells" not in parts:
            raise ConfigError(
                "algo.terms.object_map.coeff: needs the camera's object cells in the privileged state "
                "(+env.camera.object_cells=8)"
            )
        if not all(isinstance(encoder.conv[-1], SpatialSoftmax) for encoder in encoders.values()):
            raise ConfigError("algo.terms.object_map.coeff: needs the keypoint encoder (model=cnn_keypoints)")
        # The last convolution's output, before its ELU: an ELU floors a map at -1, and a map pushed
        # below zero everywhere stops learning (trained alone at a rate of 3e-3 it did, at once).
        last_convs = [last_conv(encoder) for encoder in encoders.values()]
        self.index = torch.arange(*parts["object_cells"])
        self.image_sizes = [int(shape[-1]) for shape in image_shapes.values()]
        self.window = map_window(model_cfg.kernel_sizes, model_cfg.strides)
        self.taps = [MapTap() for _ in last_convs]
        for conv, tap in zip(last_convs, self.taps):
            conv.register_forward_hook(tap)
        self.kept: list[torch.Tensor] = []

    def keep(self) -> None:
        """Keep the maps of the forward pass just run: the one the loss reads (later passes, the
        target's next images, overwrite the taps). The taps let go of them: a map that carries a
        graph cannot be deep-copied with the actor."""
        self.kept = [tap.maps for tap in self.taps]
        for tap in self.taps:
            tap.maps = None

    def loss(self, minibatch: TensorDictBase) -> torch.Tensor:
        """Mean cross-entropy over the encoders and the images where the object shows."""
        cells = minibatch[PRIVILEGED_KEY][..., self.index].float()
        total = cells.new_zeros(())
        for maps, image in zip(self.kept, self.image_sizes):
            cross_entropy, _, shows = map_cross_entropy(maps, cells, image, self.window)
            shows = shows.float()
            total = total + (cross_entropy * shows).sum() / shows.sum().clamp_min(1.0)
        count, self.kept = len(self.kept), []
        return total / count
