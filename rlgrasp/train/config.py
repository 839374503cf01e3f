"""Structured-config schemas for training, registered in Hydra's ConfigStore.

The YAML files under ``configs/`` name these schemas in their defaults lists, so a typo, a wrong
type or an unknown key fails at start with Hydra's message naming the key, instead of deep inside
a worker process minutes later.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import OmegaConf

#: The real environment factory; ``env.factory`` can point at a stand-in for debugging.
DEFAULT_ENV_FACTORY = "rlgrasp.envs:make_torchrl_env"


@dataclass
class EnvConfig:
    """Keyword arguments of the env factory (``factory`` names it as ``module:function``)."""

    factory: str = DEFAULT_ENV_FACTORY
    # The plain gymnasium env, used when collector.vector=gym_sync (one SyncVectorEnv per worker).
    gym_factory: str = "rlgrasp.envs:PandaGraspEnv"
    control_mode: str = "ee_delta"
    randomization: str = "default"
    max_episode_steps: int = 50
    # Timing: one control step = substeps x time_step seconds of simulation.
    time_step: float = 1.0 / 240.0
    substeps: int = 12
    reward: str = "dense"
    terminate_on_success: bool = False
    # Further env keywords (e.g. ``+env.kwargs.ee_yaw=true``), passed through unchanged.
    kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass
class PPOConfig:
    """PPO hyperparameters (names follow TorchRL's ``ClipPPOLoss``/``GAE`` keywords)."""

    name: str = "ppo"
    gamma: float = 0.9
    gae_lambda: float = 0.9
    epochs: int = 10
    minibatch_size: int = 512
    lr: float = 3e-4
    anneal_lr: bool = True
    min_lr_frac: float = 0.0
    clip_epsilon: float = 0.2
    entropy_coeff: float = 0.0
    critic_coeff: float = 0.5
    loss_critic_type: str = "l2"
    normalize_advantage: bool = True
    max_grad_norm: float = 0.5
    # Stop the epochs of one update once the approximate KL exceeds this (null disables).
    target_kl: float | None = 0.05
    adam_eps: float = 1e-5
    gae_every_epoch: bool = True


@dataclass
class MLPConfig:
    """Actor and critic MLPs; the observation normalizer sits inside both."""

    name: str = "mlp"
    hidden_sizes: list[int] = field(default_factory=lambda: [256, 256, 256])
    activation: str = "tanh"
    init_log_std: float = -0.5
    # Floor of the state-independent std: keeps long runs from collapsing exploration.
    min_std: float = 0.05
    obs_norm: bool = True
    obs_clip: float = 10.0


@dataclass
class RayConfig:
    """Where ``collector.backend=ray`` runs its collector actors (one per worker)."""

    # null: start a private local Ray bound to node_ip_address; "auto" or "host:6379": join a cluster.
    address: str | None = None
    node_ip_address: str = "127.0.0.1"
    num_cpus: int | None = None  # local Ray only (null: all cores)
    cpus_per_worker: float = 1.0
    memory_per_worker_gb: float = 1.0
    include_dashboard: bool = False


@dataclass
class CollectorConfig:
    """How frames are collected: ``backend=process`` (TorchRL Collector), ``ray`` (collector actors on a
    Ray cluster) or ``single`` (in-process)."""

    backend: str = "process"
    num_workers: int = 2
    envs_per_worker: int = 4
    steps_per_env: int = 128
    # "gym_sync": one gymnasium SyncVectorEnv per worker wrapped once for TorchRL (one TensorDict
    # conversion per batch step, measured faster); "serial": TorchRL SerialEnv of per-env wrappers.
    vector: str = "gym_sync"
    torch_threads: int = 1
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class LoggerConfig:
    backend: str = "tensorboard"
    console_interval_s: float = 5.0


@dataclass
class EvalConfig:
    """Deterministic evaluation on separately seeded episodes, run in-process between updates."""

    interval_frames: int = 20_000
    episodes: int = 16
    # The evaluation at the end of training (the number train() returns): more episodes than the
    # periodic ones, for a tighter interval on the figure users quote. null: same as ``episodes``.
    final_episodes: int | None = None
    num_envs: int = 8
    seed_offset: int = 1_000_000


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

    env: EnvConfig = field(default_factory=EnvConfig)
    algo: PPOConfig = field(default_factory=PPOConfig)
    model: MLPConfig = field(default_factory=MLPConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    paths: PathsConfig = field(default_factory=PathsConfig)
    experiment_name: str = "default"
    seed: int = 0
    # "auto": CUDA when available, else CPU.
    device: str = "auto"
    total_frames: int = 200_000
    # Wall-clock budget in minutes (null = none); training stops cleanly when it runs out.
    time_budget_min: float | None = None
    # null, or a run directory to continue (its checkpoints/last.pt).
    resume: str | None = None


def _first_not_none(value: Any, fallback: Any) -> Any:
    return fallback if value is None else value


def _sum(*values: int) -> int:
    return sum(values)


def register_configs() -> None:
    """Register the schemas (idempotent), the ``rlgrasp_or`` resolver used by ``hydra.run.dir`` and
    ``rlgrasp_sum`` (``configs/hydra/launcher/slurm.yaml``: CPUs = collector workers + the learner)."""
    if not OmegaConf.has_resolver("rlgrasp_or"):
        OmegaConf.register_new_resolver("rlgrasp_or", _first_not_none)
    if not OmegaConf.has_resolver("rlgrasp_sum"):
        OmegaConf.register_new_resolver("rlgrasp_sum", _sum)
    cs = ConfigStore.instance()
    cs.store(name="train_schema", node=TrainConfig)
    cs.store(group="env", name="env_schema", node=EnvConfig)
    cs.store(group="algo", name="ppo_schema", node=PPOConfig)
    cs.store(group="model", name="mlp_schema", node=MLPConfig)
    cs.store(group="collector", name="collector_schema", node=CollectorConfig)
    cs.store(group="logger", name="logger_schema", node=LoggerConfig)
    cs.store(group="paths", name="paths_schema", node=PathsConfig)
