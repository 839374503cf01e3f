"""PPO's config schema (``algo=ppo``: ``configs/algo/ppo.yaml`` names ``ppo_schema``) and its checks.

Each algorithm's keys grouped by role, as TorchRL's sota configs do: loss (the objective's keywords,
TorchRL's loss and value-estimator names), optim (the optimizer and how many gradient steps it takes on
how much data), schedule (how a rate changes over the run), pretrain (behaviour cloning before the
first frame), terms (auxiliary losses beside the algorithm's own, each built by its ``_target_``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from rlgrasp.algos.common import rate_checks
from rlgrasp.algos.registry import Check


@dataclass
class PPOLossConfig:
    """``ClipPPOLoss`` and ``GAE`` keywords."""

    gamma: float = 0.9
    gae_lambda: float = 0.9
    # Recompute advantages with the current critic each epoch (TorchRL's sota PPO); false: once per
    # update (CleanRL), cheaper.
    gae_every_epoch: bool = True
    clip_epsilon: float = 0.2
    entropy_coeff: float = 0.0
    critic_coeff: float = 0.5
    loss_critic_type: str = "l2"
    normalize_advantage: bool = True


@dataclass
class PPOOptimConfig:
    """Adam, and the epochs of minibatches over each batch."""

    lr: float = 3e-4
    adam_eps: float = 1e-5
    max_grad_norm: float = 0.5
    epochs: int = 10
    minibatch_size: int = 512


@dataclass
class PPOScheduleConfig:
    """The learning rate over the run, and when an update's epochs stop early."""

    anneal_lr: bool = True  # linearly to min_lr_frac x optim.lr at total_frames
    min_lr_frac: float = 0.0
    # The schedule's length in frames; null: total_frames. A sweep trial sets the experiment's, so that
    # it stops part-way along the real run's schedule (sweep.trial.lr_schedule=experiment).
    anneal_lr_frames: int | None = None
    # Stop the epochs of one update once the approximate KL exceeds this (null disables).
    target_kl: float | None = 0.05
    # KL-adaptive learning rate (rsl_rl's "adaptive" schedule): after each minibatch the rate is divided
    # by 1.5 when the KL estimate is above 2 x desired_kl and multiplied by 1.5 below desired_kl / 2,
    # within [1e-5, 1e-2]. It starts at optim.lr and replaces the linear annealing. null: off.
    desired_kl: float | None = None
    # The first frames train the critic alone, the actor held still: a fresh critic's first advantages
    # are noise, and would pull a trained actor away from what it does well.
    critic_warmup_frames: int = 0


@dataclass
class PretrainConfig:
    """Behaviour cloning on ``algo.demos`` before a fresh run's first frame (PPO also fits its critic
    to the demonstrations' returns); ``epochs: 0``: none. ``only``: pre-train, evaluate, stop (the
    BC baseline; PPO)."""

    epochs: int = 0
    lr: float = 1e-3
    minibatch_size: int = 64
    only: bool = False


@dataclass
class ImitationTermConfig:
    """DAPG (``rlgrasp.demos.bc.Imitation``): each minibatch's loss gains coeff x decay**k x a
    behaviour-cloning loss on minibatch_size demonstrated steps at update k; on when ``algo.demos``
    is set and coeff > 0."""

    _target_: str = "rlgrasp.demos.bc.Imitation"
    coeff: float = 0.1
    decay: float = 0.95
    minibatch_size: int = 256


@dataclass
class TeacherTermConfig:
    """A camera run's state teacher (``rlgrasp.vision.teacher_term``; a checkpoint or run): each
    minibatch's loss gains coeff x decay**k x the squared error between the actor's action and the
    teacher's on the same states (their privileged entry) at update k; during the critic's warm-up
    too, so there the actor goes on imitating while the critic learns. checkpoint null: off."""

    _target_: str = "rlgrasp.vision.teacher_term.TeacherImitation"
    checkpoint: str | None = None
    coeff: float = 1.0
    decay: float = 1.0


@dataclass
class RNDTermConfig:
    """Random Network Distillation (``rlgrasp.algos.ppo.rnd``): coeff x the intrinsic advantage joins
    PPO's (0: off)."""

    _target_: str = "rlgrasp.algos.ppo.rnd.RND"
    coeff: float = 0.0
    gamma: float = 0.99  # intrinsic returns are non-episodic
    features: int = 64
    update_fraction: float = 0.25  # of each minibatch trains the predictor


@dataclass
class PPOTermsConfig:
    """PPO's auxiliary terms: each node's ``_target_`` is the class that builds it (a class of your
    own with ``from_config(node, algorithm)`` may join them under a new name)."""

    imitation: ImitationTermConfig = field(default_factory=ImitationTermConfig)
    teacher: TeacherTermConfig = field(default_factory=TeacherTermConfig)
    rnd: RNDTermConfig = field(default_factory=RNDTermConfig)


@dataclass
class PPOConfig:
    """Clipped PPO with GAE (``rlgrasp.algos.ppo``)."""

    _target_: str = "rlgrasp.algos.ppo.PPO"  # the Algorithm class (rlgrasp.train.algorithm)
    name: str = "ppo"
    loss: PPOLossConfig = field(default_factory=PPOLossConfig)
    optim: PPOOptimConfig = field(default_factory=PPOOptimConfig)
    schedule: PPOScheduleConfig = field(default_factory=PPOScheduleConfig)
    # A demonstration directory (rlgrasp-demos; referenced, not copied) for pretrain and
    # terms.imitation (docs/sparse.md). null: none.
    demos: str | None = None
    pretrain: PretrainConfig = field(default_factory=PretrainConfig)
    terms: PPOTermsConfig = field(default_factory=PPOTermsConfig)
    # Fine-tuning (rlgrasp/train/warm_start.py): a fresh run's actor starts from this checkpoint's policy
    # (a distilled camera student, or any policy of this run's model and env), its std from
    # model.init_log_std. null: a fresh actor.
    init_from: str | None = None


SCHEMA = PPOConfig


def check(cfg: Any, batch: int, camera: Any) -> list[Check]:
    """PPO's keys; and a state run's model must be a state one (a camera's is the core's check)."""
    a, model = cfg.algo, cfg.model
    state_model = (
        "model",
        model.name,
        camera or model.name != "cnn",
        "needs a camera (e.g. cameras=wrist_depth) or model=mlp",
    )
    return [*_ppo_checks(a, batch), *_ppo_term_checks(a, camera), state_model]


def _ppo_checks(a: Any, batch: int) -> list[Check]:
    """PPO's loss, optimizer and schedule."""
    loss, o, s = a.loss, a.optim, a.schedule
    return [
        ("algo.optim.epochs", o.epochs, o.epochs >= 1, "must be >= 1"),
        *rate_checks("algo.optim.lr", o.lr),
        ("algo.optim.max_grad_norm", o.max_grad_norm, o.max_grad_norm > 0, "must be > 0"),
        (
            "algo.optim.minibatch_size",
            o.minibatch_size,
            1 <= o.minibatch_size <= max(batch, 1),
            f"must be between 1 and the batch size ({batch:,} frames = workers x envs_per_worker x "
            "steps_per_env)",
        ),
        ("algo.loss.gamma", loss.gamma, 0 < loss.gamma <= 1, "must be in (0, 1]"),
        ("algo.loss.gae_lambda", loss.gae_lambda, 0 <= loss.gae_lambda <= 1, "must be in [0, 1]"),
        ("algo.loss.clip_epsilon", loss.clip_epsilon, 0 < loss.clip_epsilon < 1, "must be in (0, 1)"),
        (
            "algo.loss.loss_critic_type",
            loss.loss_critic_type,
            loss.loss_critic_type in ("l1", "l2", "smooth_l1"),
            "must be l1, l2 or smooth_l1",
        ),
        ("algo.schedule.min_lr_frac", s.min_lr_frac, 0 <= s.min_lr_frac <= 1, "must be in [0, 1]"),
        (
            "algo.schedule.target_kl",
            s.target_kl,
            s.target_kl is None or s.target_kl > 0,
            "must be > 0 or null",
        ),
        (
            "algo.schedule.desired_kl",
            s.desired_kl,
            s.desired_kl is None or s.desired_kl > 0,
            "must be > 0 or null (null: the learning rate anneals linearly)",
        ),
        (
            "algo.schedule.anneal_lr_frames",
            s.anneal_lr_frames,
            s.anneal_lr_frames is None or s.anneal_lr_frames > 0,
            "must be > 0 or null (null: total_frames)",
        ),
        (
            "algo.schedule.critic_warmup_frames",
            s.critic_warmup_frames,
            s.critic_warmup_frames >= 0,
            "must be >= 0 (0: the actor learns from the first update)",
        ),
    ]


def _ppo_term_checks(a: Any, camera: Any) -> list[Check]:
    """PPO's pre-training and auxiliary terms: demonstrations and curiosity (``rlgrasp.demos``,
    ``rlgrasp.algos.ppo.rnd``) for state policies only, a teacher for camera policies only."""
    state, p, t = not camera, a.pretrain, a.terms
    imitation, teacher, rnd = t.get("imitation"), t.get("teacher"), t.get("rnd")
    checks = [
        ("algo.pretrain.epochs", p.epochs, p.epochs >= 0, "must be >= 0 (0: no pre-training)"),
        *rate_checks("algo.pretrain.lr", p.lr),
        ("algo.pretrain.minibatch_size", p.minibatch_size, p.minibatch_size >= 1, "must be >= 1"),
        ("algo.pretrain.epochs", p.epochs, not p.epochs or a.demos, "needs algo.demos=<demonstrations>"),
        ("algo.pretrain.only", p.only, not p.only or p.epochs > 0, "needs algo.pretrain.epochs > 0"),
        ("algo.demos", a.demos, not a.demos or state, "needs a state policy (cameras=none)"),
    ]
    if imitation is not None:
        checks += _decaying_term_checks("imitation", imitation)
        checks.append(
            (
                "algo.terms.imitation.minibatch_size",
                imitation.minibatch_size,
                imitation.minibatch_size >= 1,
                "must be >= 1",
            )
        )
    if teacher is not None:
        checks += _decaying_term_checks("teacher", teacher)
        checks.append(
            (
                "algo.terms.teacher.checkpoint",
                teacher.checkpoint,
                not teacher.checkpoint or not state,
                "labels a camera run's privileged state: needs a camera (e.g. cameras=wrist_depth)",
            )
        )
    return checks + (_rnd_checks(rnd, state) if rnd is not None else [])


def _decaying_term_checks(name: str, term: Any) -> list[Check]:
    return [
        (f"algo.terms.{name}.coeff", term.coeff, term.coeff >= 0, "must be >= 0 (0: no such term)"),
        (f"algo.terms.{name}.decay", term.decay, 0 < term.decay <= 1, "must be in (0, 1]"),
    ]


def _rnd_checks(rnd: Any, state: bool) -> list[Check]:
    return [
        ("algo.terms.rnd.coeff", rnd.coeff, rnd.coeff >= 0, "must be >= 0 (0: no curiosity)"),
        ("algo.terms.rnd.coeff", rnd.coeff, not rnd.coeff or state, "needs a state policy (cameras=none)"),
        ("algo.terms.rnd.gamma", rnd.gamma, 0 < rnd.gamma <= 1, "must be in (0, 1]"),
        ("algo.terms.rnd.features", rnd.features, rnd.features >= 1, "must be >= 1"),
        (
            "algo.terms.rnd.update_fraction",
            rnd.update_fraction,
            0 < rnd.update_fraction <= 1,
            "must be in (0, 1]",
        ),
    ]
