"""DAgger's config schema (``algo=distill``: ``configs/algo/distill.yaml`` names ``distill_schema``) and
its checks: a state teacher distilled into a camera student."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from omegaconf import MISSING

from rlgrasp.algos.common import AuxTermConfig, colour_checks, learner_threads_check, rate_checks
from rlgrasp.algos.registry import Check


@dataclass
class DistillOptimConfig:
    """Adam on the student; gradient samples per batch = epochs x the batch's frames, drawn from every
    labelled frame so far."""

    lr: float = 1e-3
    epochs: int = 16
    minibatch_size: int = 512
    # The deployed student (what acts, is evaluated and exported) is an exponential moving average of
    # the trained weights with this decay per update; 0: the trained weights themselves.
    ema_decay: float = 0.0


@dataclass
class DistillScheduleConfig:
    """Who acts, and the learning rate, over the run."""

    beta0: float = 1.0  # probability that the teacher acts, in the first batch
    beta_decay: float = 0.8  # ... times this per batch: soon the student acts, the teacher labels
    min_lr_frac: float = 0.1  # the learning rate anneals linearly to this fraction at total_frames


@dataclass
class DistillReplayConfig:
    buffer_frames: int = 60_000  # labelled frames kept (the oldest go first); 64x64 depth: 16 kB each


@dataclass
class DistillTermsConfig:
    aux: AuxTermConfig = field(default_factory=AuxTermConfig)


@dataclass
class ImageAugmentConfig:
    """Training images changed per sample (rlgrasp/vision/augment.py)."""

    kind: str = "none"  # none | colour (RGB only: channels permuted, brightness and contrast scaled)
    grey: float = 0.0  # with kind=colour: the share of training images made grey
    shift: int = 0  # each training image moved by up to this many pixels (0: not moved)
    overlay: float = 0.0  # RGB: each blended with a training-texture pattern, weight drawn in [0, overlay]


@dataclass
class DistillConfig:
    """DAgger distillation of a state teacher into a camera student (``rlgrasp.algos.dagger``)."""

    _target_: str = "rlgrasp.algos.dagger.DAgger"  # the Algorithm class (rlgrasp.train.algorithm)
    name: str = "distill"
    # A state policy's checkpoint or run directory (its last.pt); relative paths are tried from the
    # working directory, then from the repository root (policies/grasp_ppo.pt).
    teacher: str = MISSING
    optim: DistillOptimConfig = field(default_factory=DistillOptimConfig)
    schedule: DistillScheduleConfig = field(default_factory=DistillScheduleConfig)
    replay: DistillReplayConfig = field(default_factory=DistillReplayConfig)
    terms: DistillTermsConfig = field(default_factory=DistillTermsConfig)
    augment: ImageAugmentConfig = field(default_factory=ImageAugmentConfig)
    learner_threads: int | None = None  # null: every core (the learner, not the workers, is the bound)


SCHEMA = DistillConfig


def check(cfg: Any, batch: int, camera: Any) -> list[Check]:
    """DAgger's keys (a camera-less env is refused by the algorithm itself, naming its student)."""
    return _distill_checks(cfg.algo, camera)


def _distill_checks(a: Any, camera: Any) -> list[Check]:
    o, s, aug = a.optim, a.schedule, a.augment
    return [
        ("algo.optim.epochs", o.epochs, o.epochs >= 1, "must be >= 1"),
        *rate_checks("algo.optim.lr", o.lr),
        ("algo.optim.minibatch_size", o.minibatch_size, o.minibatch_size >= 1, "must be >= 1"),
        ("algo.optim.ema_decay", o.ema_decay, 0 <= o.ema_decay < 1, "must be in [0, 1) (0: no averaging)"),
        ("algo.schedule.min_lr_frac", s.min_lr_frac, 0 <= s.min_lr_frac <= 1, "must be in [0, 1]"),
        ("algo.schedule.beta0", s.beta0, 0 <= s.beta0 <= 1, "must be in [0, 1]"),
        ("algo.schedule.beta_decay", s.beta_decay, 0 < s.beta_decay <= 1, "must be in (0, 1]"),
        (
            "algo.replay.buffer_frames",
            a.replay.buffer_frames,
            a.replay.buffer_frames >= o.minibatch_size,
            f"must be >= algo.optim.minibatch_size ({o.minibatch_size})",
        ),
        learner_threads_check(a),
        (
            "algo.terms.aux.coeff",
            a.terms.aux.coeff,
            a.terms.aux.coeff >= 0,
            "must be >= 0 (0: no auxiliary task)",
        ),
        *colour_checks(aug, camera),
        ("algo.augment.shift", aug.shift, 0 <= aug.shift <= 16, "must be in [0, 16] pixels"),
    ]
