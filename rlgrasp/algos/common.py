"""What several algorithms' schemas share: config pieces (the camera learners' auxiliary task) and the
helpers their checks are written with. No torch: the schemas are read without it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from rlgrasp.algos.registry import Check

#: The colour augmentations a camera learner can train with (``algo.augment.kind``), named here so that
#: the schemas need no import of ``rlgrasp.vision.augment``, which implements them.
AUGMENTATIONS = ("none", "colour")


@dataclass
class AuxTermConfig:
    """A camera learner's image features also predict these parts of the privileged state, weighted coeff
    (0: off; rlgrasp/vision/auxiliary.py). Training only; nothing is deployed."""

    coeff: float = 0.0
    parts: list[str] = field(default_factory=lambda: ["object_minus_grasp", "grasped"])


def positive(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0


def rate_checks(key: str, value: Any) -> list[Check]:
    return [(key, value, positive(value) and math.isfinite(value), "must be finite and > 0")]


def learner_threads_check(a: Any) -> Check:
    threads = a.learner_threads
    return (
        "algo.learner_threads",
        threads,
        threads is None or threads >= 1,
        "must be >= 1 or null (every core)",
    )


def colour_checks(aug: Any, camera: Any) -> list[Check]:
    """``algo.augment.kind``, ``grey`` and ``overlay``, the same for a DAgger student and a camera SAC:
    the colour augmentations and the overlay change RGB images only, so a camera without RGB refuses
    them rather than train without them."""
    rgb = bool(camera) and camera.get("modality", "depth") in ("rgb", "rgbd")
    needs_rgb = "needs a camera with RGB (e.g. cameras=wrist_rgb)"
    return [
        (
            "algo.augment.kind",
            aug.kind,
            aug.kind in AUGMENTATIONS,
            f"must be one of {', '.join(AUGMENTATIONS)}",
        ),
        ("algo.augment.kind", aug.kind, aug.kind == "none" or rgb, f"recolours RGB images; {needs_rgb}"),
        (
            "algo.augment.grey",
            aug.grey,
            0 <= aug.grey <= 1 and (aug.grey == 0 or aug.kind == "colour"),
            "must be in [0, 1], and 0 unless algo.augment.kind=colour",
        ),
        ("algo.augment.overlay", aug.overlay, 0 <= aug.overlay <= 1, "must be in [0, 1] (0: no overlay)"),
        ("algo.augment.overlay", aug.overlay, aug.overlay == 0 or rgb, f"overlays RGB images; {needs_rgb}"),
    ]


def ground_swap_checks(aug: Any, camera: Any) -> list[Check]:
    """``algo.augment.ground_swap`` reads the camera's ground mask, which only an RGB camera draws."""
    masked = bool(camera) and bool(camera.get("ground_mask", False))
    share = aug.ground_swap
    return [
        ("algo.augment.ground_swap", share, 0 <= share <= 1, "must be in [0, 1] (0: none)"),
        (
            "algo.augment.ground_swap",
            share,
            share == 0 or masked,
            "needs the camera's ground mask: an RGB camera and +env.camera.ground_mask=true",
        ),
    ]


def hidden_checks(key: str, sizes: Any, activation_key: str, activation: Any) -> list[Check]:
    """An MLP's ``hidden_sizes`` and ``activation`` (the model's, a critic's)."""
    return [
        (
            key,
            list(sizes),
            len(sizes) > 0 and all(positive(h) for h in sizes),
            "must be a non-empty list of positive sizes",
        ),
        (activation_key, activation, activation in ("tanh", "relu", "elu"), "must be tanh, relu or elu"),
    ]
