"""Every config schema, in one place, and the validation of a training config.

The YAML files under ``configs/`` name these schemas in their defaults lists, so a typo, a wrong
type or an unknown key fails at start with Hydra's message naming the key, instead of deep inside a
worker process minutes later. Each default is written once, here; the YAML files carry only what
differs from it. Training (``train.yaml``), evaluation (``eval.yaml``) and sweeps
(``sweep/<name>.yaml``) are three separate trees; ``rlgrasp.compose`` composes them outside a
command line.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from hydra.core.config_store import ConfigStore
from hydra.utils import instantiate
from omegaconf import MISSING, OmegaConf

from rlgrasp.envs.randomization import Randomizer
from rlgrasp.rundir import register_resolvers
from rlgrasp.utils import plain

#: The Hydra config tree (``configs/`` next to the package in a source checkout).
CONFIG_DIR = os.environ.get("RLGRASP_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))


# --- training ---------------------------------------------------------------------------------
@dataclass
class EnvConfig:
    """``PandaGraspEnv``'s constructor as a ``_target_`` node: every keyword, with its default.

    Built everywhere with ``hydra.utils.instantiate(cfg.env, _partial_=True)`` (see
    ``rlgrasp.envs.factory.env_factory``); a test checks that the fields mirror the constructor.
    """

    _target_: str = "rlgrasp.envs.PandaGraspEnv"
    control_mode: str = "ee_delta"  # ee_delta | joint_delta | joint_torque
    # A preset name (the `randomization` config group sets it) or a mapping of ranges.
    randomization: Any = "default"
    max_episode_steps: int = 50
    # One control step = substeps x time_step seconds of simulation.
    time_step: float = 1.0 / 240.0
    substeps: int = 12
    # The task part (the `task` config group sets it): a `_target_` node of rlgrasp.envs.tasks (lift,
    # pick_place, push, stack, or a task class of your own) with its keywords, e.g. env.task.reward=sparse,
    # env.task.weights={lift: 4}. Typed Any: each task checks its own keywords (docs/tasks.md).
    task: Any = "lift"
    ee_step: float = 0.04
    ee_yaw: bool = False
    yaw_step: float = 0.2
    joint_step: float = 0.05
    torque_fraction: float = 0.3
    gravity_compensation: bool = True
    render_mode: str | None = None
    render_width: int = 320
    render_height: int = 240
    camera_distance: float = 1.1
    camera_yaw: float = 60.0
    camera_pitch: float = -25.0
    solver_iterations: int = 20
    # An arm of rlgrasp.envs.robot.ROBOTS (the `robot` config group sets it) or a user's arm as a
    # mapping of rlgrasp.envs.robot_spec.RobotSpec keys (docs/robots.md).
    robot: Any = "panda"
    robot_urdf: str | None = None  # null: the arm's own model file
    # A set name (the `objects` config group sets it), a list of set names, or a mapping with
    # sets / paths / max_width / scale: see rlgrasp/envs/objects.py.
    objects: Any = "cube"
    # null, or a camera (rlgrasp.envs.cameras.CameraSpec keys); the `cameras` config group sets it.
    camera: Any = None
    visual: str = "none"  # none | default | wide | heldout (the `visual` config group)
    # mesh: the arm's own collision meshes; primitive: boxes and capsules for the Panda's hand and
    # fingers (rlgrasp/envs/collision_model.py). The shipped policies were trained on the meshes.
    collision_model: str = "mesh"


# --- algorithms: each one's keys grouped by role, as TorchRL's sota configs do -----------------
# loss: the objective's keywords (TorchRL's loss and value-estimator names); optim: the optimizer and
# how many gradient steps it takes on how much data; schedule: how a rate changes over the run;
# replay: what is kept between batches; pretrain: behaviour cloning before the first frame; terms:
# auxiliary losses beside the algorithm's own. The flat keys of before (algo.lr, ...) are mapped by
# ALGO_KEYS below: old checkpoints load (rlgrasp.train.legacy) and an old override names its new key.
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
    """Random Network Distillation (``rlgrasp.train.rnd``): coeff x the intrinsic advantage joins
    PPO's (0: off)."""

    _target_: str = "rlgrasp.train.rnd.RND"
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


@dataclass
class SACLossConfig:
    """``SACLoss`` keywords, and the target critics' soft update."""

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
class AuxTermConfig:
    """A camera learner's image features also predict these parts of the privileged state, weighted coeff
    (0: off; rlgrasp/vision/auxiliary.py). Training only; nothing is deployed."""

    coeff: float = 0.0
    parts: list[str] = field(default_factory=lambda: ["object_minus_grasp", "grasped"])


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


#: Where each flat ``algo`` key of before lives now (``algo.<key>`` -> ``algo.<path>``), for every
#: algorithm; ``teacher`` is the PPO term's checkpoint (DAgger's ``algo.teacher`` did not move).
ALGO_KEYS = {
    **{k: f"loss.{k}" for k in ("gamma", "gae_lambda", "gae_every_epoch", "clip_epsilon", "entropy_coeff")},
    **{k: f"loss.{k}" for k in ("critic_coeff", "loss_critic_type", "normalize_advantage")},
    **{k: f"loss.{k}" for k in ("tau", "num_critics", "alpha_init", "target_entropy")},
    **{k: f"optim.{k}" for k in ("lr", "adam_eps", "max_grad_norm", "epochs", "minibatch_size", "ema_decay")},
    **{
        k: f"optim.{k}"
        for k in ("actor_lr", "critic_lr", "alpha_lr", "batch_size", "utd_ratio", "actor_every")
    },
    **{
        k: f"schedule.{k}"
        for k in ("anneal_lr", "min_lr_frac", "anneal_lr_frames", "target_kl", "desired_kl")
    },
    **{k: f"schedule.{k}" for k in ("critic_warmup_frames", "beta0", "beta_decay")},
    **{k: f"replay.{k}" for k in ("buffer_frames", "learning_starts", "demo_ratio")},
    "save_replay": "replay.save",
    **{f"critic_{k}": f"critic.{k}" for k in ("hidden_sizes", "activation", "layer_norm", "privileged")},
    **{f"bc_{k}": f"pretrain.{k}" for k in ("epochs", "lr", "minibatch_size", "only")},
    **{f"demo_{k}": f"terms.imitation.{k}" for k in ("coeff", "decay", "minibatch_size")},
    "bc_coeff": "terms.imitation.coeff",
    "teacher": "terms.teacher.checkpoint",
    **{f"teacher_{k}": f"terms.teacher.{k}" for k in ("coeff", "decay")},
    **{f"rnd_{k}": f"terms.rnd.{k}" for k in ("coeff", "gamma", "features", "update_fraction")},
    **{f"aux_{k}": f"terms.aux.{k}" for k in ("coeff", "parts")},
    "augment": "augment.kind",
    **{f"augment_{k}": f"augment.{k}" for k in ("grey", "shift")},
    "image_shift": "augment.shift",
}


def moved_algo_key(key: str, algo_name: str | None = None) -> str | None:
    """Today's path of a flat ``algo`` key of before (``lr`` -> ``optim.lr``); None for a key that
    did not move (``demos``, ``init_from``, DAgger's ``teacher``) or never existed."""
    if key == "teacher" and algo_name == "distill":
        return None
    return ALGO_KEYS.get(key)


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


@dataclass
class CollectorConfig:
    """How frames are collected: ``_target_`` is the backend, a class of ``rlgrasp.train.collectors``
    built from the other keys (``collector=process``: TorchRL's collector over worker processes;
    ``single``: in-process; ``ray``: collector actors on a Ray cluster). Each worker steps one
    gymnasium ``SyncVectorEnv`` of ``envs_per_worker`` envs and runs the actor on the whole batch;
    frames per batch = workers x envs_per_worker x steps_per_env."""

    _target_: str = "rlgrasp.train.collectors.ProcessCollector"
    num_workers: int = 2  # 0: in-process
    envs_per_worker: int = 4
    steps_per_env: int = 128
    torch_threads: int = 1
    # Collect the next batch while the learner updates (one update of lag; rlgrasp/train/batches.py, ppo.py).
    overlap: bool = True
    # Cut each env's first episode at a different length so that a worker's envs are not in phase:
    # needed when steps_per_env is short against an episode (rlgrasp/train/collect.py StaggeredStart).
    stagger_starts: bool = False
    # A batch not delivered within this many seconds ends the run (a worker that hangs, not dies: a
    # checkpoint is saved and the run stops in one line, instead of waiting for ever).
    worker_timeout_s: float = 600.0


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
    """DAgger distillation of a state teacher into a camera student (``rlgrasp.vision.distill``)."""

    _target_: str = "rlgrasp.vision.distill.DAgger"  # the Algorithm class (rlgrasp.train.algorithm)
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


@dataclass
class RayConfig:
    """Where ``collector=ray`` runs its collector actors (one per worker)."""

    # null: start a private local Ray bound to node_ip_address; "auto" or "host:6379": join a cluster.
    address: str | None = None
    # Local Ray only: stay on loopback unless told otherwise (set the node's address to go multi-machine).
    node_ip_address: str = "127.0.0.1"
    num_cpus: int | None = None  # local Ray only (null: all cores)
    cpus_per_worker: float = 1.0  # Ray resources each collector actor reserves
    memory_per_worker_gb: float = 1.0
    include_dashboard: bool = False


@dataclass
class RayCollectorConfig(CollectorConfig):
    """``collector=ray``: the process backend's keys plus where Ray runs (``collector.ray.*``)."""

    _target_: str = "rlgrasp.train.collectors.RayCollector"
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class LoggerConfig:
    """Where the run's curves go: ``_target_`` is a class of ``rlgrasp.train.logger`` (``logger=
    tensorboard``; ``none``: the console only) or ``rlgrasp.train.trackers`` (``wandb``, ``mlflow``:
    TensorBoard plus the tracker), built from the other keys."""

    _target_: str = "rlgrasp.train.logger.TensorBoardLogger"
    console_interval_s: float = 5.0  # the console's progress line at most this often


@dataclass
class TrackerLoggerConfig(LoggerConfig):
    """``logger=wandb`` / ``logger=mlflow``: TensorBoard plus a tracker (``rlgrasp.train.trackers``)."""

    project: str = "rlgrasp"  # W&B project / MLflow experiment
    tags: list[str] = field(default_factory=list)  # run tags in the tracker's UI
    run_name: str | None = None  # null: <experiment_name>/<run dir name>


@dataclass
class WandbLoggerConfig(TrackerLoggerConfig):
    _target_: str = "rlgrasp.train.trackers.WandbLogger"
    entity: str | None = None  # W&B team or user (null: your default)
    # online | offline | disabled (null: $WANDB_MODE, else online).
    mode: str | None = None


@dataclass
class MlflowLoggerConfig(TrackerLoggerConfig):
    _target_: str = "rlgrasp.train.trackers.MlflowLogger"
    # A server (http://...), a database (sqlite:///...) or a folder (file:...); null: $MLFLOW_TRACKING_URI,
    # else the folder outputs/mlruns.
    tracking_uri: str | None = None


@dataclass
class PeriodicEvalConfig:
    """Training's own evaluation: deterministic actions on separately seeded episodes."""

    interval_frames: int = 20_000
    episodes: int = 16
    # The evaluation at the end of training (the number train() returns): more episodes than the
    # periodic ones, for a tighter interval on the figure users quote. null: same as ``episodes``.
    final_episodes: int | None = 100
    num_envs: int = 8
    seed_offset: int = 1_000_000
    # The periodic evaluations in a process of their own (rlgrasp.train.eval_process) while training
    # goes on; each result is logged at the frames of the weights it evaluated, and picked up when the
    # next one is due (so a sweep's pruner hears of it one interval later). false: in the learner's
    # process, training waits. The final evaluation runs in the learner's process, shared with the
    # evaluation process when this one started it (the later rounds there, the same figures).
    background: bool = False
    # null: the training env's randomization. A preset, a ranges file or ranges over a preset, as
    # rlgrasp-eval's `randomization` (e.g. eval.randomization=default): a run whose training ranges
    # move (ADR, a curriculum) is judged, and its best checkpoint chosen, on the ranges it aims at.
    randomization: Any = None


@dataclass
class CheckpointConfig:
    interval_frames: int = 50_000
    keep_last: int = 3


@dataclass
class PathsConfig:
    root_dir: str = "."
    output_dir: str = "${hydra:runtime.output_dir}"


@dataclass
class TrainConfig:
    """Top-level schema; the groups are filled by the defaults list of ``configs/train.yaml``."""

    # A `_target_` node, validated by its group's schema (env_schema for env=grasp).
    env: Any = MISSING
    # The `algo` and `model` groups choose a schema each (ppo | distill, mlp | cnn).
    algo: Any = MISSING
    model: Any = MISSING
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    eval: PeriodicEvalConfig = field(default_factory=PeriodicEvalConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    paths: PathsConfig = field(default_factory=PathsConfig)
    experiment_name: str = "default"
    seed: int = 0
    device: str = "auto"  # "auto": CUDA when available, else CPU
    total_frames: int = 200_000
    # Wall-clock budget in minutes (null = none); training stops cleanly when it runs out.
    time_budget_min: float | None = None
    # null; a run directory to continue in place (its newest readable checkpoint: frames, curves, lr)
    # or a checkpoint file; or "auto": the newest run of this experiment and seed if any, else fresh.
    resume: str | None = None


# --- demonstrations (rlgrasp-demos) -----------------------------------------------------------
@dataclass
class DemosConfig:
    """``rlgrasp-demos``'s config (``configs/demos.yaml``): which episodes to record, and where."""

    env: Any = MISSING  # the training env node (env, objects, randomization groups)
    episodes: int = 100
    out: str = MISSING  # the file goes to <out>/demos
    policy: str = "scripted"  # scripted, or a checkpoint file / run directory whose policy acts
    keep: str = "success"  # success: only successful episodes; all: every episode with its outcome
    seed: int = 0  # episode i is reset with seed + i
    workers: int = 2  # processes (1: in this one); the file does not depend on it


# --- evaluation (rlgrasp-eval) ----------------------------------------------------------------
@dataclass
class EvalConfig:
    """``rlgrasp-eval``'s config (``configs/eval.yaml``): how to evaluate a policy."""

    policy: str = "checkpoint"  # checkpoint | scripted | random (baselines need no ckpt)
    ckpt: str | None = None  # a run directory (-> checkpoints/<ckpt_kind>.pt) or a checkpoint file
    ckpt_kind: str = "best"  # best | last, when ckpt is a run directory
    episodes: int = 100
    seed: int = 0  # episode i is reset with seed + i
    # null: the randomization the policy was trained with, or its run's eval.randomization when the run
    # set one (baselines: the env's default, `default`).
    # A preset (none | default | wide) or explicit ranges over a base preset, e.g.
    #   'randomization={preset:default,object_mass:[0.5,1.0],finger_force:[5,10]}'
    # (randomization=wide alone selects the training config group, which sets env.randomization.)
    randomization: Any = None
    # Env keywords over the checkpoint's env config, e.g. env.max_episode_steps=80 (as in training;
    # rlgrasp.overrides adds the `+`). objects=random_urdfs_test or objects={paths:[...]} set env.objects.
    env: dict[str, Any] = field(default_factory=dict)
    # Worker processes (1 = in this process); results do not depend on it. A spawned worker pays
    # the imports first: use 2+ for long evaluations.
    workers: int = 1
    deterministic: bool = True  # false: sample from the policy's distribution (seeded per episode)
    # A camera policy's teacher, evaluated on the same seeded episodes (it reads `privileged`):
    # auto = the checkpoint's teacher if it has one (algo.teacher, algo.terms.teacher.checkpoint); none;
    # or a checkpoint file / run directory.
    teacher: str = "auto"
    video: bool = True
    video_episodes: int = 3  # the first K episodes are rendered
    video_format: str = "auto"  # auto (mp4 if ffmpeg exists, else gif) | gif | mp4
    plots: bool = True
    tensorboard: bool = True  # when evaluating a run, log scalars and video frames to its TensorBoard
    name: str | None = None  # output folder name; null: a timestamp
    out_dir: str | None = None  # explicit output directory (overrides the default location)
    # Baselines and loose checkpoint files go to <outputs_root>/eval/...
    outputs_root: str = "outputs"


# --- sweeps (rlgrasp-sweep) -------------------------------------------------------------------
@dataclass
class SamplerConfig:
    """``name``: tpe | random | cmaes | qmc | gp; ``kwargs`` go to the Optuna sampler unchanged."""

    name: str = "tpe"
    seed: int | None = 0
    kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass
class PrunerConfig:
    """``name``: median | percentile | hyperband | successive_halving | threshold | none."""

    name: str = "median"
    kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass
class TrialBudget:
    """What one trial may spend; overrides the experiment's own ``total_frames``/``time_budget_min``."""

    total_frames: int = 100_000
    time_budget_min: float | None = None
    # One run per seed, in turn, with the same parameters; the trial's value is their mean and the
    # pruner sees the first seed's evaluations. Empty: one run with the training config's seed.
    seeds: list[int] = field(default_factory=list)
    # Over how many frames the learning rate anneals: "trial" (trial.total_frames: the trial ends at
    # lr 0) or "experiment" (the experiment's total_frames: the trial is the start of the real run).
    lr_schedule: str = "trial"


@dataclass
class SweepObjective:
    """What a trial scores (``rlgrasp.sweep.score``). ``final``: the last evaluation's ``metric``.
    ``first_reach`` (minimize): F x (1 - tie_break x final success), F the env frames at the first
    evaluation whose ``metric`` >= ``threshold``; a run that never reaches it scores
    trial.total_frames x (2 - final success), worse than any run that does."""

    kind: str = "final"  # final | first_reach
    threshold: float = 0.9
    tie_break: float = 0.01


@dataclass
class SweepConfig:
    study_name: str = "sweep"
    n_trials: int = 20
    # Metric of the periodic evaluation to optimize and report to the pruner (first_reach: the one
    # compared to the threshold, success_rate).
    metric: str = "success_rate"
    objective: SweepObjective = field(default_factory=SweepObjective)
    direction: str | None = None  # null: the objective's (final: maximize, first_reach: minimize)
    # null: journal file <root_dir>/<study_name>/journal.log; a path: a journal file there;
    # a URL with "://" (sqlite:///x.db, postgresql://...): Optuna's RDB storage.
    storage: str | None = None
    root_dir: str = "outputs/sweeps"
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    pruner: PrunerConfig = field(default_factory=PrunerConfig)
    trial: TrialBudget = field(default_factory=TrialBudget)
    # Training overrides applied to every trial (after the command line's, before the trial's params).
    overrides: list[str] = field(default_factory=list)
    # Nested training keys; each leaf is a distribution {type: float|int|categorical, ...}.
    params: dict[str, Any] = field(default_factory=dict)
    # Parameter sets tried first (nested like params), e.g. the experiment's current values.
    enqueue: list[Any] = field(default_factory=list)
    # Added to sampler.seed so that cooperating processes (sweep.worker=1, 2, ...) sample differently.
    worker: int = 0
    timeout_min: float | None = None  # this process stops starting trials after this long
    summary_only: bool = False  # write the summary of the stored study and exit
    plots: bool = True


#: The primary config ``compose_sweep`` composes: only the ``sweep`` group.
SWEEP_PRIMARY = "rlgrasp_sweep_primary"


def _sum(*values: int) -> int:
    return sum(values)


#: The colour augmentations a camera student can train with (``algo.augment.kind``), named here so that the
#: schema needs no import of ``rlgrasp.vision.augment``, which implements them.
AUGMENTATIONS = ("none", "colour")


class ConfigError(ValueError):
    """A bad training input; the message is one line naming the key, its value and what is allowed."""


def register_configs() -> None:
    """Register every schema (idempotent) and the resolvers the YAML files call: ``rlgrasp_sum``
    (OmegaConf has no arithmetic; the SLURM launcher asks for workers + 1 CPUs) and the run
    directory's (``rlgrasp.rundir``)."""
    if not OmegaConf.has_resolver("rlgrasp_sum"):
        OmegaConf.register_new_resolver("rlgrasp_sum", _sum)
    register_resolvers()
    cs = ConfigStore.instance()
    cs.store(name="train_schema", node=TrainConfig)
    cs.store(group="env", name="env_schema", node=EnvConfig)
    cs.store(group="algo", name="ppo_schema", node=PPOConfig)
    cs.store(group="algo", name="distill_schema", node=DistillConfig)
    cs.store(group="algo", name="sac_schema", node=SACConfig)
    cs.store(group="model", name="mlp_schema", node=MLPConfig)
    cs.store(group="model", name="cnn_schema", node=CNNConfig)
    cs.store(group="collector", name="collector_schema", node=CollectorConfig)
    cs.store(group="collector", name="ray_collector_schema", node=RayCollectorConfig)
    cs.store(group="logger", name="logger_schema", node=LoggerConfig)
    cs.store(group="logger", name="wandb_schema", node=WandbLoggerConfig)
    cs.store(group="logger", name="mlflow_schema", node=MlflowLoggerConfig)
    cs.store(group="paths", name="paths_schema", node=PathsConfig)
    cs.store(name="eval_schema", node=EvalConfig)
    cs.store(name="demos_schema", node=DemosConfig)
    cs.store(group="sweep", name="sweep_schema", node=SweepConfig)
    cs.store(name=SWEEP_PRIMARY, node={"defaults": [{"sweep": "smoke"}, "_self_"]})


# --- validation of a training config (before any worker starts) -------------------------------
def _positive(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0


def _train_problems(cfg: Any, batch: int) -> list[str]:
    """Each bad value of a composed training config as ``key=value: what is allowed``; ``batch``: the
    collector's frames per batch."""
    checks = [
        *_run_checks(cfg),
        *_collector_checks(cfg.collector),
        *_algo_checks(cfg.algo, batch, cfg.env.get("camera")),
        *_model_checks(cfg.model),
        *_model_camera_checks(cfg.model, cfg.env.get("camera"), cfg.algo.name),
        *_eval_checkpoint_checks(cfg.eval, cfg.checkpoint),
    ]
    return (
        [f"{key}={value!r}: {allowed}" for key, value, ok, allowed in checks if not ok]
        + _device_problems(cfg.device)
        + _eval_randomization_problems(cfg.eval.get("randomization"))
    )


def _run_checks(cfg: Any) -> list[tuple[str, Any, bool, str]]:
    """The run's own keys: its seed, its name (a folder) and its budgets."""
    return [
        ("seed", cfg.seed, 0 <= cfg.seed < 2**32, "must be an integer in [0, 2**32)"),
        (
            "experiment_name",
            cfg.experiment_name,
            _one_path_component(cfg.experiment_name),
            "must be a plain name (no '/', not '..' or empty): it names a folder under the outputs",
        ),
        ("total_frames", cfg.total_frames, cfg.total_frames > 0, "must be > 0"),
        (
            "time_budget_min",
            cfg.time_budget_min,
            cfg.time_budget_min is None or cfg.time_budget_min > 0,
            "must be > 0 or null",
        ),
    ]


def _collector_checks(c: Any) -> list[tuple[str, Any, bool, str]]:
    return [
        ("collector.num_workers", c.num_workers, c.num_workers >= 0, "must be >= 0 (0: in-process)"),
        ("collector.envs_per_worker", c.envs_per_worker, c.envs_per_worker >= 1, "must be >= 1"),
        ("collector.steps_per_env", c.steps_per_env, c.steps_per_env >= 1, "must be >= 1"),
        ("collector.torch_threads", c.torch_threads, c.torch_threads >= 1, "must be >= 1"),
        (
            "collector.worker_timeout_s",
            c.worker_timeout_s,
            _positive(c.worker_timeout_s),
            "must be > 0 (seconds a batch may take)",
        ),
    ]


def _model_checks(m: Any) -> list[tuple[str, Any, bool, str]]:
    """The MLP's keys (a camera model's own are ``_model_camera_checks``')."""
    distribution = m.get("distribution", "tanh_normal")  # a camera model has no such key
    return [
        (
            "model.hidden_sizes",
            list(m.hidden_sizes),
            len(m.hidden_sizes) > 0 and all(_positive(h) for h in m.hidden_sizes),
            "must be a non-empty list of positive sizes",
        ),
        (
            "model.activation",
            m.activation,
            m.activation in ("tanh", "relu", "elu"),
            "must be tanh, relu or elu",
        ),
        (
            "model.distribution",
            distribution,
            distribution in ("tanh_normal", "normal"),
            "must be tanh_normal or normal",
        ),
        ("model.obs_clip", m.obs_clip, m.obs_clip > 0, "must be > 0 (the normalized observation's bound)"),
    ]


def _eval_checkpoint_checks(e: Any, k: Any) -> list[tuple[str, Any, bool, str]]:
    return [
        ("eval.episodes", e.episodes, e.episodes >= 1, "must be >= 1"),
        (
            "eval.final_episodes",
            e.final_episodes,
            e.final_episodes is None or e.final_episodes >= 1,
            "must be >= 1 or null",
        ),
        ("eval.num_envs", e.num_envs, e.num_envs >= 1, "must be >= 1"),
        ("checkpoint.keep_last", k.keep_last, k.keep_last >= 1, "must be >= 1"),
        (
            "checkpoint.interval_frames",
            k.interval_frames,
            k.interval_frames >= 0,
            "must be >= 0 (0: only at the end)",
        ),
    ]


def _eval_randomization_problems(spec: Any) -> list[str]:
    """A bad ``eval.randomization`` now, not at the first evaluation minutes into the run."""
    if spec is None:
        return []
    try:
        Randomizer(plain(spec))
    except (ValueError, OSError) as exc:
        return [f"eval.randomization={plain(spec)!r}: {exc}"]
    return []


def _one_path_component(name: Any) -> bool:
    """A name that stays one folder below where it is joined (no separator, no '..', not absolute)."""
    text = str(name)
    return bool(text) and text not in (".", "..") and "/" not in text and "\\" not in text


def _model_camera_checks(m: Any, camera: Any, algo: str) -> list[tuple[str, Any, bool, str]]:
    """A camera env needs a camera policy (model=cnn), a state env a state one (model=mlp); distill
    refuses a camera-less env itself, naming its student."""
    if camera:
        return [
            ("model", m.name, m.name == "cnn", "must be cnn with a camera (or cameras=none for mlp)"),
            *(_cnn_checks(m) if m.name == "cnn" else []),
        ]
    if algo == "ppo":
        return [("model", m.name, m.name != "cnn", "needs a camera (e.g. cameras=wrist_depth) or model=mlp")]
    return []


def _cnn_checks(m: Any) -> list[tuple[str, Any, bool, str]]:
    layers = f"needs one entry per layer of model.channels={list(m.channels)}"
    return [
        ("model.pooling", m.pooling, m.pooling in POOLINGS, f"must be one of {', '.join(POOLINGS)}"),
        ("model.kernel_sizes", list(m.kernel_sizes), len(m.kernel_sizes) == len(m.channels), layers),
        ("model.strides", list(m.strides), len(m.strides) == len(m.channels), layers),
    ]


def _algo_checks(a: Any, batch: int, camera: Any) -> list[tuple[str, Any, bool, str]]:
    """The checks of ``algo``'s own keys: each algorithm has its own (an unknown one is refused)."""
    if a.name == "ppo":
        return [*_ppo_checks(a, batch), *_ppo_term_checks(a, camera)]
    if a.name == "distill":
        return _distill_checks(a, camera)
    if a.name == "sac":
        return [*_sac_checks(a, camera), *_sac_demo_checks(a)]
    return [
        ("algo.name", a.name, False, "must be ppo, sac or distill (the algo group: algo=ppo|sac|distill)")
    ]


def _rate_checks(key: str, value: Any) -> list[tuple[str, Any, bool, str]]:
    return [(key, value, _positive(value) and math.isfinite(value), "must be finite and > 0")]


def _learner_threads_check(a: Any) -> tuple[str, Any, bool, str]:
    threads = a.learner_threads
    return (
        "algo.learner_threads",
        threads,
        threads is None or threads >= 1,
        "must be >= 1 or null (every core)",
    )


def _sac_checks(a: Any, camera: Any) -> list[tuple[str, Any, bool, str]]:
    """SAC's keys: a ratio > 0, a buffer that holds a minibatch, rates > 0."""
    o, r, c = a.optim, a.replay, a.critic
    rates = [("optim", "actor_lr"), ("optim", "critic_lr"), ("optim", "alpha_lr"), ("loss", "alpha_init")]
    return [
        (
            "algo.optim.utd_ratio",
            o.utd_ratio,
            _positive(o.utd_ratio),
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
        (
            "algo.critic.hidden_sizes",
            list(c.hidden_sizes),
            len(c.hidden_sizes) > 0 and all(_positive(h) for h in c.hidden_sizes),
            "must be a non-empty list of positive sizes",
        ),
        (
            "algo.critic.activation",
            c.activation,
            c.activation in ("tanh", "relu", "elu"),
            "must be tanh, relu or elu",
        ),
        ("algo.augment.shift", a.augment.shift, a.augment.shift >= 0, "must be >= 0 (pixels)"),
        *_colour_checks(a.augment, camera),
        *_ground_swap_checks(a.augment, camera),
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
        _learner_threads_check(a),
        *[check for group, key in rates for check in _rate_checks(f"algo.{group}.{key}", a[group][key])],
    ]


def _sac_demo_checks(a: Any) -> list[tuple[str, Any, bool, str]]:
    """What SAC does with demonstrations: their share of a minibatch, cloning first, the BC term."""
    p, coeff, needs = a.pretrain, a.terms.imitation.coeff, "needs algo.demos=<demonstrations>"
    return [
        ("algo.replay.demo_ratio", a.replay.demo_ratio, 0 < a.replay.demo_ratio < 1, "must be in (0, 1)"),
        ("algo.terms.imitation.coeff", coeff, coeff >= 0 and math.isfinite(coeff), "must be finite and >= 0"),
        ("algo.terms.imitation.coeff", coeff, not coeff or a.demos, needs),
        ("algo.pretrain.epochs", p.epochs, p.epochs >= 0, "must be >= 0 (0: no pre-training)"),
        ("algo.pretrain.epochs", p.epochs, not p.epochs or a.demos, needs),
        *_rate_checks("algo.pretrain.lr", p.lr),
    ]


def _ppo_checks(a: Any, batch: int) -> list[tuple[str, Any, bool, str]]:
    """PPO's loss, optimizer and schedule."""
    loss, o, s = a.loss, a.optim, a.schedule
    return [
        ("algo.optim.epochs", o.epochs, o.epochs >= 1, "must be >= 1"),
        *_rate_checks("algo.optim.lr", o.lr),
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


def _ppo_term_checks(a: Any, camera: Any) -> list[tuple[str, Any, bool, str]]:
    """PPO's pre-training and auxiliary terms: demonstrations and curiosity (``rlgrasp.demos``,
    ``rlgrasp.train.rnd``) for state policies only, a teacher for camera policies only."""
    state, p, t = not camera, a.pretrain, a.terms
    imitation, teacher, rnd = t.get("imitation"), t.get("teacher"), t.get("rnd")
    checks = [
        ("algo.pretrain.epochs", p.epochs, p.epochs >= 0, "must be >= 0 (0: no pre-training)"),
        *_rate_checks("algo.pretrain.lr", p.lr),
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


def _decaying_term_checks(name: str, term: Any) -> list[tuple[str, Any, bool, str]]:
    return [
        (f"algo.terms.{name}.coeff", term.coeff, term.coeff >= 0, "must be >= 0 (0: no such term)"),
        (f"algo.terms.{name}.decay", term.decay, 0 < term.decay <= 1, "must be in (0, 1]"),
    ]


def _rnd_checks(rnd: Any, state: bool) -> list[tuple[str, Any, bool, str]]:
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


def _distill_checks(a: Any, camera: Any) -> list[tuple[str, Any, bool, str]]:
    o, s, aug = a.optim, a.schedule, a.augment
    return [
        ("algo.optim.epochs", o.epochs, o.epochs >= 1, "must be >= 1"),
        *_rate_checks("algo.optim.lr", o.lr),
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
        _learner_threads_check(a),
        (
            "algo.terms.aux.coeff",
            a.terms.aux.coeff,
            a.terms.aux.coeff >= 0,
            "must be >= 0 (0: no auxiliary task)",
        ),
        *_colour_checks(aug, camera),
        ("algo.augment.shift", aug.shift, 0 <= aug.shift <= 16, "must be in [0, 16] pixels"),
    ]


def _colour_checks(aug: Any, camera: Any) -> list[tuple[str, Any, bool, str]]:
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


def _ground_swap_checks(aug: Any, camera: Any) -> list[tuple[str, Any, bool, str]]:
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


def _device_problems(device: str) -> list[str]:
    if device in ("auto", "cpu"):
        return []
    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError):
        return [f"device={device!r}: must be auto, cpu, cuda or cuda:<n>"]
    if dev.type == "cuda" and not torch.cuda.is_available():
        return [f"device={device!r}: CUDA is not available on this machine (use device=cpu or auto)"]
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        return [f"device={device!r}: this machine has {torch.cuda.device_count()} CUDA device(s)"]
    if dev.type not in ("cpu", "cuda"):
        return [f"device={device!r}: must be auto, cpu, cuda or cuda:<n>"]
    return []


def _built(key: str, node: Any, build: Callable[[Any], Any]) -> Any:
    """``build(node)`` for a ``_target_`` node; ``ConfigError`` naming the target when it fails."""
    try:
        return build(node)
    except Exception as exc:  # noqa: BLE001 - Hydra wraps whatever the target raised
        reason = " ".join(str(exc).split(", set env var HYDRA_FULL_ERROR")[0].split())[:300]
        raise ConfigError(f"{key}._target_={node.get('_target_')!r} cannot be built: {reason}") from None


def _warn_about_workers(workers: int) -> None:
    """Far more worker processes than cores is allowed (a shared machine may lend more later) but
    slows every one of them: say so."""
    cores = os.cpu_count() or 1
    if workers > 2 * cores:
        logging.getLogger("rlgrasp.train").warning(
            "collector.num_workers=%d on a machine with %d cores: each worker gets a fraction of a core "
            "(collector.num_workers=%d or fewer is usually fastest)",
            workers,
            cores,
            cores,
        )


def validate_train(cfg: Any) -> None:
    """Refuse a training config with a bad value: ``ConfigError`` naming the first (and how many
    more). The env's own keywords are checked by the env when the learner builds it, before workers."""
    if OmegaConf.is_config(cfg) and cfg.env.get("_target_") == EnvConfig._target_:
        try:
            OmegaConf.merge(OmegaConf.structured(EnvConfig), cfg.env)
        except Exception as exc:  # noqa: BLE001 - OmegaConf's validation errors
            raise ConfigError(f"env: {str(exc).splitlines()[0]}") from None
    collector = _built("collector", cfg.collector, lambda node: instantiate(node, _convert_="all"))
    _built("logger", cfg.logger, lambda node: instantiate(node, _partial_=True))  # built with the run dir
    _warn_about_workers(cfg.collector.num_workers)
    problems = _train_problems(cfg, collector.frames_per_batch)
    if problems:
        more = f" (and {len(problems) - 1} more: {'; '.join(problems[1:])})" if len(problems) > 1 else ""
        raise ConfigError(problems[0] + more)
