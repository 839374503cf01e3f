"""Colour augmentation of a student's RGB training images: what a colour camera must not rely on.

Visual randomization varies hues, textures and light within its ranges, and a student learns
exactly those ranges: one that keys on hue fails on hues it never saw (the held-out visual set's).
So each RGB image of a minibatch is also recoloured before the student sees it: its channels
permuted (hue moves by thirds of the circle and swaps), its brightness and contrast scaled, and,
with probability ``grey``, its hue dropped altogether (luminance in all three channels), so that
the student also finds the object by brightness and texture (tried against the held-out set, which
draws object and ground from one hue range: no gain; its loss is the rings on the ground). The labels stay:
the teacher acts on the state, which no colour changes. Applied in the learner only; rollouts and
evaluation see the camera's own images.

``shift`` (any image, depth too) moves each training image by up to that many pixels each way, its
border repeated: the random shift of DrQ (Kostrikov et al. 2020), so that an encoder cannot key on
where in the image an edge lies (measured on the objects students, depth and RGB: no gain in
success, docs/benchmarks/cameras.md). Hand-written: TorchRL's image transforms crop every image of a
batch alike, and a shift must be drawn per image.

``overlay`` (RGB) blends each training image with a pattern from a bank of the training texture
generators' (never the held-out rings), at a weight drawn per image in ``[0, overlay]``: SODA's and
SVEA's overlay (Hansen et al. 2021), procedural patterns standing in for their natural images, so
that strong edges and colours anywhere in the image, not only the ground texture cells an episode
happens to show, stop looking like the object. A camera SAC overlays the images its losses read and
not the next images the targets are computed from (SVEA's clean targets).

``ground_swap`` (RGB, with the camera's ground mask) replaces, in that share of the images, the
pixels where the ground shows by a pattern of the training generators (never the held-out rings),
at the image's scale or magnified: the same replayed image comes back on many grounds, the object
and the arm as they were, so that nothing of the ground's look tells where the object is. Green-
screen background swapping, with the simulator's segmentation as the screen; it needs a mask a
real camera lacks, so it is a training aid for simulation only.
"""

from __future__ import annotations

from functools import lru_cache

import torch
from tensordict import TensorDictBase

from rlgrasp.envs.visuals import VISUAL_PRESETS, repaint_patterns

PERMUTATIONS = torch.tensor([[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]])
LUMINANCE = torch.tensor([0.299, 0.587, 0.114])  # ITU-R BT.601 weights, as PIL's convert("L")
OVERLAY_PATTERNS = 256  # in the bank, each also flipped left to right
GROUND_PATTERNS = 256  # in the ground bank, each also flipped left to right
# A wrist camera sees a ground texture's cells anywhere from a few pixels to the whole image across.
GROUND_SCALES = (1, 2, 4, 8)


def recolour(
    rgb: torch.Tensor,
    generator: torch.Generator | None = None,
    brightness: tuple[float, float] = (0.6, 1.3),
    contrast: tuple[float, float] = (0.7, 1.3),
    grey: float = 0.0,
) -> torch.Tensor:
    """``[..., 3, H, W]`` uint8 images, each with its channels permuted (or, with probability
    ``grey``, replaced by its luminance) and its brightness and contrast scaled by factors drawn per
    image; float out, in 0-255 (the encoder scales either)."""
    shape = rgb.shape
    x = rgb.reshape(-1, 3, shape[-2] * shape[-1]).float()
    n = x.shape[0]
    # Each image's recolouring is affine, x' = s M x + (1 - s) mean(M x), with M a permutation times
    # the brightness gain and s the contrast: three multiply-adds over the pixels do all of it (a
    # batched product of 3x3 matrices, torch.bmm, is slow on a CPU: docs/history/algorithms.md).
    # The draws are made on the CPU, where ``generator`` lives, and moved to the images' device.
    mix = torch.eye(3)[PERMUTATIONS[torch.randint(len(PERMUTATIONS), (n,), generator=generator)]]
    greyed = torch.rand(n, generator=generator) < grey
    mix[greyed] = LUMINANCE.expand(3, 3)
    mix *= torch.empty(n, 1, 1).uniform_(*brightness, generator=generator)
    spread = torch.empty(n, 1, 1).uniform_(*contrast, generator=generator)
    mix, spread = mix.to(x.device), spread.to(x.device)
    mean = torch.bmm(mix, x.mean(-1, keepdim=True)).mean(1, keepdim=True)
    gain = spread * mix  # gain[:, i, j]: how much input channel j adds to output channel i
    out = gain[:, :, 0:1] * x[:, 0:1]
    out.addcmul_(gain[:, :, 1:2], x[:, 1:2]).addcmul_(gain[:, :, 2:3], x[:, 2:3])
    return out.add_((1 - spread) * mean).clamp_(0, 255).reshape(shape)


def random_shift(images: torch.Tensor, pad: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``[N, C, H, W]`` images (any dtype), each moved by whole pixels drawn in [-pad, pad] per axis
    and per image; the pixels shifted in repeat the border."""
    n, channels, height, width = images.shape
    device = images.device
    offsets = (torch.randint(2 * pad + 1, (2, n), generator=generator) - pad).to(device)
    rows = (torch.arange(height, device=device) + offsets[0, :, None]).clamp_(0, height - 1)
    cols = (torch.arange(width, device=device) + offsets[1, :, None]).clamp_(0, width - 1)
    # One gather over the flattened pixels: several times faster than padding, then cropping each image.
    source = (rows[:, :, None] * width + cols[:, None, :]).reshape(n, 1, -1).expand(n, channels, -1)
    return images.reshape(n, channels, -1).gather(2, source).reshape(images.shape)


def _pattern_bank(
    height: int, width: int, count: int, seed: int, scales: tuple[int, ...], device: torch.device | str
) -> torch.Tensor:
    """``[2 * count, 3, height, width]`` uint8 patterns in the training visuals' hues, each also
    flipped left to right, on ``device``: the same bank for the same arguments in every run."""
    hues = VISUAL_PRESETS["default"].hues
    bank = torch.from_numpy(repaint_patterns((height, width), hues, count, seed=seed, scales=scales))
    return torch.cat([bank, bank.flip(-1)]).to(device)


@lru_cache(maxsize=4)
def overlay_bank(height: int, width: int, device: torch.device | str = "cpu") -> torch.Tensor:
    """``[2 * OVERLAY_PATTERNS, 3, height, width]`` patterns, float in 0-255 (converted once, not per
    step), made once per image size and device."""
    return _pattern_bank(height, width, OVERLAY_PATTERNS, 0, (1,), device).float()


def overlay(rgb: torch.Tensor, strength: float, generator: torch.Generator | None = None) -> torch.Tensor:
    """``[..., 3k, H, W]`` images (``k`` stacked frames), each blended with a pattern of the bank:
    ``(1 - w) x + w p``, ``w`` drawn per image in ``[0, strength]``; float out, in 0-255."""
    shape = rgb.shape
    x = rgb.reshape(-1, 3, shape[-2], shape[-1]).float()
    bank = overlay_bank(shape[-2], shape[-1], x.device)
    n = x.shape[0]
    pattern = bank[torch.randint(len(bank), (n,), generator=generator).to(x.device)]
    weight = torch.empty(n, 1, 1, 1).uniform_(0.0, strength, generator=generator).to(x.device)
    return torch.lerp(x, pattern, weight).reshape(shape)  # a new tensor: float input is not changed


@lru_cache(maxsize=4)
def ground_bank(height: int, width: int, device: torch.device | str = "cpu") -> torch.Tensor:
    """``[2 * GROUND_PATTERNS, 3, height, width]`` uint8 grounds, a quarter each at the image's scale
    and magnified 2, 4 and 8 times (``GROUND_SCALES``), made once per image size and device."""
    return _pattern_bank(height, width, GROUND_PATTERNS, 1, GROUND_SCALES, device)


def swap_ground(
    rgb: torch.Tensor, mask: torch.Tensor, share: float, generator: torch.Generator | None = None
) -> torch.Tensor:
    """``[N, 3k, H, W]`` images (``k`` stacked frames) and their ``[N, k, H, W]`` ground masks: in
    ``share`` of the images, drawn per image, the ground's pixels take a pattern of the bank (the
    same one in each stacked frame); the rest as they were."""
    n, _, height, width = rgb.shape
    frames = mask.shape[1]
    device = rgb.device
    bank = ground_bank(height, width, device)
    swapped = (torch.rand(n, generator=generator) < share).to(device)
    pattern = bank[torch.randint(len(bank), (n,), generator=generator).to(device)].to(rgb.dtype)
    ground = (mask * swapped[:, None, None, None]).to(rgb.dtype)[:, :, None]  # [N, k, 1, H, W], 0 or 1
    images = rgb.reshape(n, frames, 3, height, width)
    # x + (p - x) g is p where g is 1 and x where it is 0, exactly: uint8 arithmetic wraps modulo 256
    # both ways, and floats hold 0-255 integers exactly. A CPU does it several times faster than a
    # torch.where broadcasting the mask over the channels.
    return (images + (pattern[:, None] - images) * ground).reshape(rgb.shape)


def augment_images(
    images: torch.Tensor,
    key: str,
    kind: str,
    grey: float = 0.0,
    shift: int = 0,
    overlay_strength: float = 0.0,
    ground_mask: torch.Tensor | None = None,
    ground_swap: float = 0.0,
) -> torch.Tensor:
    """One batch of ``key`` images (``depth`` or ``rgb``): RGB ones with their ground swapped
    (``ground_swap`` > 0, where ``ground_mask`` says), then shifted (``shift`` pixels) and, RGB,
    overlaid with patterns (``overlay_strength`` > 0) and, with ``kind="colour"``, recoloured; each
    image its own draw."""
    if ground_swap > 0 and key == "rgb" and ground_mask is not None:
        images = swap_ground(images, ground_mask, ground_swap)
    if shift > 0:
        images = random_shift(images, shift)
    if overlay_strength > 0 and key == "rgb":
        images = overlay(images, overlay_strength)
    if kind == "colour" and key == "rgb":
        images = recolour(images, grey=grey)
    return images


def augment(
    sample: TensorDictBase, kind: str, grey: float = 0.0, shift: int = 0, overlay_strength: float = 0.0
) -> TensorDictBase:
    """A minibatch with its images shifted (``shift`` pixels; depth and RGB) and its RGB images
    overlaid (``overlay_strength``) and recoloured (``kind="colour"``)."""
    for key in ("depth", "rgb"):
        if key in sample.keys():
            sample[key] = augment_images(sample[key], key, kind, grey, shift, overlay_strength)
    return sample
