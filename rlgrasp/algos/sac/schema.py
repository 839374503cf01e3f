"""SAC's config schema (``algo=sac``: ``configs/algo/sac.yaml`` names ``sac_schema``) and its checks.

Keys grouped by role: loss (the losses' settings and the target critics' soft update), optim (Adam
for each part, and the update-to-data ratio), replay, critic (the Q-networks), pretrain and terms
(with demonstrations: RLPD, behaviour cloning), augment and encoder (a camera learner's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from rlgrasp.algos.common import (
    AuxTermConfig,
    colour_checks,
    ground_swap_checks,
    hidden_checks,
    learner_threads_check,
    positive,
    rate_checks,
)
from rlgrasp.algos.registry import Check


@dataclass
class SACLossConfig:
    """The losses' settings (``rlgrasp.algos.sac.losses``), and the target critics' soft update."""

    gamma: float = 0.95
    num_critics: int = 2  # the target is the minimum over them (RLPD: an ensemble, e.g. 10)
    alpha_init: float = 0.1  # the entropy temperature's start (rewards here are at most 1 a step)
    target_entropy: float | None = None  # null: -(action size)
    tau: float = 0.005  # the target critics' soft-update rate


@dataclass
class SACOptimConfig:
    """Adam for each part, and how many gradient steps the learner takes on how much data."""

    actor_lr: float = 3e-4
    critic_lr: float = 3e-4
    alpha_lr: float = 3e-4
    batch_size: int = 256
    # Gradient steps per env frame, kept across batches (0.25: one step per four frames).
    utd_ratio: float = 0.25
    actor_every: int = 1  # the actor and temperature step every this many critic steps


@dataclass
class ReplayConfig:
    """The replay buffer."""

    buffer_frames: int = 300_000  # transitions kept (the oldest go first)
    learning_starts: int = 5_000  # frames in the buffer before the first gradient step
    # With algo.demos: this share of each minibatch is drawn from them (RLPD's symmetric sampling).
    demo_ratio: float = 0.5
    # The buffer is written beside the checkpoints (<run>/replay/, each checkpoint the transitions
    # stored since the last), so a resumed run continues with it; false: it starts with an empty one.
    save: bool = True


@dataclass
class SACCriticConfig:
    """The Q-networks (the actor is ``model``'s)."""

    hidden_sizes: list[int] = field(default_factory=lambda: [256, 256])
    activation: str = "relu"  # tanh | relu | elu
    layer_norm: bool = True  # LayerNorm after each hidden layer (RLPD)
    # With a camera: the critics also read the privileged state beside the images' features (never
    # deployed; an asymmetric actor-critic).
    privileged: bool = True


@dataclass
class SACPretrainConfig:
    """With ``algo.demos``: this many epochs of behaviour cloning on them (at ``lr``) before the first
    frame (0: none)."""

    epochs: int = 0
    lr: float = 1e-3


@dataclass
class SACImitationConfig:
    """With ``algo.demos``: the actor's loss also pulls its deterministic action towards the
    demonstrated one on the demonstrations' rows of each minibatch, weighted coeff (0: RLPD alone)."""

    coeff: float = 0.0


@dataclass
class ObjectMapTermConfig:
    """With the keypoint encoder and the camera's object cells: the encoder's first keypoint map trained
    onto the object's pixels, weighted coeff (0: off; rlgrasp/vision/object_map.py). Training only."""

    coeff: float = 0.0


@dataclass
class SACTermsConfig:
    imitation: SACImitationConfig = field(default_factory=SACImitationConfig)
    aux: AuxTermConfig = field(default_factory=AuxTermConfig)  # with a camera
    object_map: ObjectMapTermConfig = field(default_factory=ObjectMapTermConfig)  # with a camera


@dataclass
class ReplayAugmentConfig:
    """Replayed images moved by up to ``shift`` pixels each way (DrQ-v2; 0: not moved) and, with
    ``kind=colour``, RGB images recoloured as a DAgger student's are (rlgrasp/vision/augment.py)."""

    shift: int = 4
    kind: str = "none"  # none | colour (RGB only: channels permuted, brightness and contrast scaled)
    grey: float = 0.0  # with kind=colour: the share of replayed images made grey
    # RGB: each replayed image blended with a training-texture pattern at a weight drawn in [0, overlay]
    # (not the next images, the targets'); 0: none
    overlay: float = 0.0
    # RGB, with the camera's ground mask (env.camera.ground_mask): the share of replayed images whose
    # ground pixels take a training-texture pattern (not the next images, the targets'); 0: none
    ground_swap: float = 0.0


#: Where a relabelled transition's new goal comes from (``algo.her.strategy``; rlgrasp.algos.sac.her).
HER_STRATEGIES = ("future", "final")


@dataclass
class HERConfig:
    """Hindsight experience replay (Andrychowicz et al. 2017; ``rlgrasp.algos.sac.her``): on a goal task
    with the sparse reward, ``relabel_ratio`` of each online minibatch's rows take, in place of their
    desired goal, where the object was after a later step of the same episode (``future``) or after its
    last stored step (``final``), and the reward that goal pays. A failed episode then still teaches
    how to put the object somewhere. Demonstrations' rows are not relabelled."""

    enabled: bool = False
    strategy: str = "future"  # future | final
    # 0.8: SB3's and RL Zoo's n_sampled_goal=4 (four relabelled rows for each one kept)
    relabel_ratio: float = 0.8


#: The losses that may train a camera SAC's image encoders (``algo.encoder.trained_by``).
ENCODER_TRAINERS = ("critic", "actor", "both")


@dataclass
class SACEncoderConfig:
    """With a camera: which losses train the image encoders. ``critic``: the critics' (DrQ-v2; the
    actor reads the features detached). ``actor``: the actor's, through the features it reads (the
    asymmetric actor-critic's way, Pinto et al. 2018, for critics that read the privileged state and
    need little from the images; the critics read the features detached). ``both``: the two summed."""

    trained_by: str = "critic"


@dataclass
class SACConfig:
    """Soft actor-critic (``rlgrasp.algos.sac``), and with ``demos`` RLPD: demonstrations sampled
    beside online data in every minibatch."""

    _target_: str = "rlgrasp.algos.sac.SAC"  # the Algorithm class (rlgrasp.train.algorithm)
    name: str = "sac"
    loss: SACLossConfig = field(default_factory=SACLossConfig)
    optim: SACOptimConfig = field(default_factory=SACOptimConfig)
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    her: HERConfig = field(default_factory=HERConfig)  # hindsight relabelling of a goal task's replay
    critic: SACCriticConfig = field(default_factory=SACCriticConfig)
    demos: str | None = None  # a demonstrations directory (rlgrasp-demos)
    pretrain: SACPretrainConfig = field(default_factory=SACPretrainConfig)
    terms: SACTermsConfig = field(default_factory=SACTermsConfig)
    augment: ReplayAugmentConfig = field(default_factory=ReplayAugmentConfig)
    encoder: SACEncoderConfig = field(default_factory=SACEncoderConfig)  # with a camera
    init_from: str | None = None  # a checkpoint of this env and model whose actor starts this run
    # Torch threads for the updates (null: every core). A camera learner's run is bound by its
    # updates while the workers mostly wait, so it takes every core (grasp_vision_sac); 1 keeps a
    # state learner's runs as they were measured.
    learner_threads: int | None = 1


SCHEMA = SACConfig


def check(cfg: Any, batch: int, camera: Any) -> list[Check]:
    """SAC's keys (a subclass's schema, TQC's, adds its own to these)."""
    return [*_sac_checks(cfg.algo, camera), *_sac_demo_checks(cfg.algo), *_her_checks(cfg, camera)]


def _sac_checks(a: Any, camera: Any) -> list[Check]:
    """SAC's keys: a ratio > 0, a buffer that holds a minibatch, rates > 0."""
    o, r, c = a.optim, a.replay, a.critic
    rates = [("optim", "actor_lr"), ("optim", "critic_lr"), ("optim", "alpha_lr"), ("loss", "alpha_init")]
    return [
        (
            "algo.optim.utd_ratio",
            o.utd_ratio,
            positive(o.utd_ratio),
            "must be > 0 (gradient steps per env frame)",
        ),
        ("algo.optim.batch_size", o.batch_size, o.batch_size >= 1, "must be >= 1"),
        ("algo.optim.actor_every", o.actor_every, o.actor_every >= 1, "must be >= 1"),
        (
            "algo.replay.buffer_frames",
            r.buffer_frames,
            r.buffer_frames >= o.batch_size,
            f"must be >= algo.optim.batch_size ({o.batch_size}): the buffer must hold a minibatch",
        ),
        (
            "algo.replay.learning_starts",
            r.learning_starts,
            0 <= r.learning_starts <= r.buffer_frames,
            "must be between 0 and algo.replay.buffer_frames",
        ),
        ("algo.loss.gamma", a.loss.gamma, 0 < a.loss.gamma <= 1, "must be in (0, 1]"),
        ("algo.loss.tau", a.loss.tau, 0 < a.loss.tau <= 1, "must be in (0, 1]"),
        ("algo.loss.num_critics", a.loss.num_critics, a.loss.num_critics >= 1, "must be >= 1"),
        *hidden_checks("algo.critic.hidden_sizes", c.hidden_sizes, "algo.critic.activation", c.activation),
        ("algo.augment.shift", a.augment.shift, a.augment.shift >= 0, "must be >= 0 (pixels)"),
        *colour_checks(a.augment, camera),
        *ground_swap_checks(a.augment, camera),
        (
            "algo.encoder.trained_by",
            a.encoder.trained_by,
            a.encoder.trained_by in ENCODER_TRAINERS,
            "must be " + ", ".join(ENCODER_TRAINERS[:-1]) + " or " + ENCODER_TRAINERS[-1],
        ),
        ("algo.terms.aux.coeff", a.terms.aux.coeff, a.terms.aux.coeff >= 0, "must be >= 0 (0: off)"),
        (
            "algo.terms.object_map.coeff",
            a.terms.object_map.coeff,
            a.terms.object_map.coeff >= 0,
            "must be >= 0 (0: off)",
        ),
        learner_threads_check(a),
        *[check for group, key in rates for check in rate_checks(f"algo.{group}.{key}", a[group][key])],
    ]


def _sac_demo_checks(a: Any) -> list[Check]:
    """What SAC does with demonstrations: their share of a minibatch, cloning first, the BC term."""
    p, coeff, needs = a.pretrain, a.terms.imitation.coeff, "needs algo.demos=<demonstrations>"
    return [
        ("algo.replay.demo_ratio", a.replay.demo_ratio, 0 < a.replay.demo_ratio < 1, "must be in (0, 1)"),
        ("algo.terms.imitation.coeff", coeff, coeff >= 0 and math.isfinite(coeff), "must be finite and >= 0"),
        ("algo.terms.imitation.coeff", coeff, not coeff or a.demos, needs),
        ("algo.pretrain.epochs", p.epochs, p.epochs >= 0, "must be >= 0 (0: no pre-training)"),
        ("algo.pretrain.epochs", p.epochs, not p.epochs or a.demos, needs),
        *rate_checks("algo.pretrain.lr", p.lr),
    ]


def _her_checks(cfg: Any, camera: Any) -> list[Check]:
    """HER's keys, and what it needs of the run: a state learner (it rewrites the flat observation's
    goal entries; a camera learner's goal is also in its images' scene) and the sparse reward (the only
    one a relabelled goal's reward can be recomputed for: the dense terms read the arm and the grasp
    at that step, which the replay does not keep). That the task has goals, and the success rule HER
    recomputes, is read from the env when the learner builds it (``rlgrasp.algos.sac.her.goal_layout``).
    An env without rlgrasp's task part (``env=gym``) pays a relabelled goal with its own
    ``compute_reward``, whatever its reward: its goals are checked with the env's other keys
    (``rlgrasp.envs.gym_env.check_config``)."""
    h = cfg.algo.get("her")
    if h is None:  # a config written before the key
        return []
    own_reward = "task" not in cfg.env
    reward = (cfg.env.get("task") or {}).get("reward")
    return [
        (
            "algo.her.strategy",
            h.strategy,
            h.strategy in HER_STRATEGIES,
            "must be " + " or ".join(HER_STRATEGIES),
        ),
        (
            "algo.her.relabel_ratio",
            h.relabel_ratio,
            0 <= h.relabel_ratio <= 1,
            "must be in [0, 1] (the share of each online minibatch relabelled; 0.8: SB3's n_sampled_goal=4)",
        ),
        (
            "algo.her.enabled",
            h.enabled,
            not h.enabled or not camera,
            "relabels the goal in a state learner's flat observation; needs env.camera=null",
        ),
        (
            "algo.her.enabled",
            h.enabled,
            not h.enabled or own_reward or reward == "sparse",
            f"relabelled rewards are recomputed with a goal task's sparse rule; needs a goal task "
            f"(task=pick_place or task=push) with env.task.reward=sparse, not {reward!r}",
        ),
    ]
