"""Every config schema, in one place, and composing the configs outside a command line.

The YAML files under ``configs/`` name these schemas in their defaults lists, so a typo, a wrong
type or an unknown key fails at start with Hydra's message naming the key, instead of deep inside a
worker process minutes later. Each default is written once, here; the YAML files carry only what
differs from it. Training (``train.yaml``), evaluation (``eval.yaml``) and sweeps
(``sweep/<name>.yaml``) are three separate trees.
"""

from __future__ import annotations

import os
import secrets
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra import compose, initialize_config_dir
from hydra.core.config_store import ConfigStore
from hydra.experimental.callback import Callback
from hydra.utils import instantiate
from omegaconf import MISSING, DictConfig, OmegaConf

#: The Hydra config tree (``configs/`` next to the package in a source checkout).
CONFIG_DIR = os.environ.get("RLGRASP_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))


# --- training ---------------------------------------------------------------------------------
@dataclass
class EnvConfig:
    """``PandaGraspEnv``'s constructor as a ``_target_`` node: every keyword, with its default.

    Built everywhere with ``hydra.utils.instantiate(cfg.env, _partial_=True)`` (see
    ``rlgrasp.train.collect.env_factory``); a test checks that the fields mirror the constructor.
    """

    _target_: str = "rlgrasp.envs.PandaGraspEnv"
    control_mode: str = "ee_delta"  # ee_delta | joint_delta | joint_torque
    # A preset name (the `randomization` config group sets it) or a mapping of ranges.
    randomization: Any = "default"
    max_episode_steps: int = 50
    # One control step = substeps x time_step seconds of simulation.
    time_step: float = 1.0 / 240.0
    substeps: int = 12
    reward: str = "dense"
    reward_weights: dict[str, float] | None = None
    success_height: float = 0.05
    terminate_on_success: bool = False
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
    robot: str = "panda"  # an arm of rlgrasp.envs.robot.ROBOTS
    robot_urdf: str | None = None  # null: the arm's own model file
    # A set name (the `objects` config group sets it), a list of set names, or a mapping with
    # sets / paths / max_width / scale: see rlgrasp/envs/objects.py.
    objects: Any = "cube"
    # null, or a camera (rlgrasp.envs.cameras.CameraSpec keys); the `cameras` config group sets it.
    camera: Any = None
    visual: str = "none"  # none | default | wide | heldout (the `visual` config group)


@dataclass
class PPOConfig:
    """PPO hyperparameters (names follow TorchRL's ``ClipPPOLoss``/``GAE`` keywords)."""

    name: str = "ppo"
    gamma: float = 0.9
    gae_lambda: float = 0.9
    epochs: int = 10
    minibatch_size: int = 512
    lr: float = 3e-4
    anneal_lr: bool = True  # linearly to min_lr_frac x lr at total_frames
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
    # Recompute advantages with the current critic each epoch (TorchRL's sota PPO); false: once per
    # update (CleanRL), cheaper.
    gae_every_epoch: bool = True


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


@dataclass
class RayConfig:
    """Where ``collector.backend=ray`` runs its collector actors (one per worker)."""

    # null: start a private local Ray bound to node_ip_address; "auto" or "host:6379": join a cluster.
    address: str | None = None
    # Local Ray only: stay on loopback unless told otherwise (set the node's address to go multi-machine).
    node_ip_address: str = "127.0.0.1"
    num_cpus: int | None = None  # local Ray only (null: all cores)
    cpus_per_worker: float = 1.0  # Ray resources each collector actor reserves
    memory_per_worker_gb: float = 1.0
    include_dashboard: bool = False


@dataclass
class CollectorConfig:
    """How frames are collected: ``backend=process`` (TorchRL Collector over worker processes),
    ``ray`` (collector actors on a Ray cluster) or ``single`` (in-process). Each worker steps one
    gymnasium ``SyncVectorEnv`` of ``envs_per_worker`` envs and runs the actor on the whole batch;
    frames per batch = workers x envs_per_worker x steps_per_env."""

    backend: str = "process"
    num_workers: int = 2
    envs_per_worker: int = 4
    steps_per_env: int = 128
    torch_threads: int = 1
    # Collect the next batch while the learner updates (one update of lag; rlgrasp/train/batches.py, ppo.py).
    overlap: bool = True
    # Cut each env's first episode at a different length so that a worker's envs are not in phase:
    # needed when steps_per_env is short against an episode (rlgrasp/train/collect.py StaggeredStart).
    stagger_starts: bool = False
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class LoggerConfig:
    backend: str = "tensorboard"  # tensorboard | none
    console_interval_s: float = 5.0


@dataclass
class PeriodicEvalConfig:
    """Training's own evaluation: deterministic actions on separately seeded episodes, in-process."""

    interval_frames: int = 20_000
    episodes: int = 16
    # The evaluation at the end of training (the number train() returns): more episodes than the
    # periodic ones, for a tighter interval on the figure users quote. null: same as ``episodes``.
    final_episodes: int | None = 100
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

    # A `_target_` node, validated by its group's schema (env_schema for env=grasp).
    env: Any = MISSING
    algo: PPOConfig = field(default_factory=PPOConfig)
    model: MLPConfig = field(default_factory=MLPConfig)
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


# --- evaluation (rlgrasp-eval) ----------------------------------------------------------------
@dataclass
class EvalConfig:
    """``rlgrasp-eval``'s config (``configs/eval.yaml``): how to evaluate a policy."""

    policy: str = "checkpoint"  # checkpoint | scripted | random (baselines need no ckpt)
    ckpt: str | None = None  # a run directory (-> checkpoints/<ckpt_kind>.pt) or a checkpoint file
    ckpt_kind: str = "best"  # best | last, when ckpt is a run directory
    episodes: int = 100
    seed: int = 0  # episode i is reset with seed + i
    # null: the randomization the policy was trained with (baselines: the env's default, `default`).
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
    # auto = the checkpoint's algo.teacher if it has one; none; or a checkpoint file / run directory.
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


@dataclass
class SweepConfig:
    study_name: str = "sweep"
    n_trials: int = 20
    # Metric of the periodic evaluation to optimize and report to the pruner.
    metric: str = "success_rate"
    direction: str = "maximize"
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


def _first_not_none(value: Any, fallback: Any) -> Any:
    return fallback if value is None else value


def _sum(*values: int) -> int:
    return sum(values)


class ConfigError(ValueError):
    """A bad training input; the message is one line naming the key, its value and what is allowed."""


#: Run directories this process chose that did not exist before (safe to remove on a start-up error).
FRESH_RUN_DIRS: set[str] = set()
_RUN_TOKEN = secrets.token_hex(3)  # one per process: every resolution of hydra.run.dir agrees


def run_dir(resume: str | None, base: str, seed: int) -> str:
    """``hydra.run.dir``: a run directory named ``<date>_<time>_s<seed>_<random>`` under ``base``
    (two runs started in the same second never share one); ``resume=<run dir>`` that directory,
    ``resume=<run>/checkpoints/<file>.pt`` its run (any other resume: a new directory);
    ``resume=auto`` the newest run of ``base`` with this seed that holds a checkpoint, else a new one."""
    chosen = None
    if resume == "auto":
        runs = sorted(Path(base).glob(f"*_s{seed}_*/checkpoints/*.pt"), key=lambda p: p.parts[-3])
        chosen = str(runs[-1].parents[1]) if runs else None
    elif resume:  # a run, or a file in a run's checkpoints/; anything else fails later, in a new dir
        path = Path(resume)
        if path.is_dir() and any((path / "checkpoints").glob("*.pt")):
            chosen = str(path)
        elif path.is_file() and path.parent.name == "checkpoints":
            chosen = str(path.parents[1])
    if chosen is None:
        chosen = f"{base}/{time.strftime('%Y-%m-%d_%H-%M-%S')}_s{seed}_{_RUN_TOKEN}"
    if not Path(chosen).exists():
        FRESH_RUN_DIRS.add(str(Path(chosen).resolve()))
    return chosen


#: ``hydra.output_subdir`` per run directory, chosen once per Hydra run (Hydra resolves it more than
#: once, the last time after writing into it); ``RunDirCheck.on_run_start`` forgets earlier runs'.
_OUTPUT_SUBDIRS: dict[str, str] = {}


def output_subdir(output_dir: str) -> str:
    """``hydra.output_subdir``: ``.hydra`` for the first start in a run directory; every later start
    there (a resume, a requeued job) ``.hydra/resume_<n>`` (n = 1, 2, ...). Hydra writes config.yaml,
    hydra.yaml and overrides.yaml into it: in ``.hydra/`` itself a resume would overwrite the launch's."""
    key = str(Path(output_dir).resolve())
    if key not in _OUTPUT_SUBDIRS:
        hydra_dir = Path(key) / ".hydra"
        n = 0
        if (hydra_dir / "config.yaml").exists():
            n = 1
            while (hydra_dir / f"resume_{n}").exists():
                n += 1
        _OUTPUT_SUBDIRS[key] = f".hydra/resume_{n}" if n else ".hydra"
    return _OUTPUT_SUBDIRS[key]


def register_configs() -> None:
    """Register every schema (idempotent), the resolvers of ``hydra.run.dir`` (``rlgrasp_run_dir``) and
    ``hydra.output_subdir`` (``rlgrasp_output_subdir``), and ``rlgrasp_sum`` (OmegaConf has no
    arithmetic; the SLURM launcher asks for workers + 1 CPUs)."""
    if not OmegaConf.has_resolver("rlgrasp_or"):
        OmegaConf.register_new_resolver("rlgrasp_or", _first_not_none)
    if not OmegaConf.has_resolver("rlgrasp_run_dir"):
        OmegaConf.register_new_resolver("rlgrasp_run_dir", run_dir)
    if not OmegaConf.has_resolver("rlgrasp_output_subdir"):
        OmegaConf.register_new_resolver("rlgrasp_output_subdir", output_subdir)
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
    cs.store(name="eval_schema", node=EvalConfig)
    cs.store(group="sweep", name="sweep_schema", node=SweepConfig)
    cs.store(name=SWEEP_PRIMARY, node={"defaults": [{"sweep": "smoke"}, "_self_"]})
    from rlgrasp.train.trackers import register_tracker_configs  # logger=wandb|mlflow (extends LoggerConfig)

    register_tracker_configs()


def compose_config(
    name: str, overrides: list[str] | tuple[str, ...] = (), config_dir: str | Path = CONFIG_DIR
) -> DictConfig:
    """``configs/<name>.yaml`` with ``overrides``, as its script would build it (without Hydra's
    run-time keys: pass ``paths.output_dir=...`` for training)."""
    register_configs()
    with initialize_config_dir(config_dir=str(Path(config_dir).resolve()), version_base="1.3"):
        return compose(config_name=name, overrides=list(overrides))


def compose_train(
    overrides: list[str] | tuple[str, ...] = (), config_dir: str | Path = CONFIG_DIR
) -> DictConfig:
    """A training config as ``scripts/train.py`` would build it."""
    return compose_config("train", overrides, config_dir)


def compose_eval(
    overrides: list[str] | tuple[str, ...] = (), config_dir: str | Path = CONFIG_DIR
) -> DictConfig:
    """An evaluation config as ``scripts/evaluate.py`` would build it."""
    return compose_config("eval", overrides, config_dir)


def compose_sweep(
    overrides: list[str] | tuple[str, ...] = (), config_dir: str | Path = CONFIG_DIR
) -> DictConfig:
    """The ``sweep`` node composed from ``configs/sweep/<name>.yaml`` and ``sweep.*`` overrides."""
    return compose_config(SWEEP_PRIMARY, overrides, config_dir).sweep


def env_factory(env_cfg: DictConfig | Mapping[str, Any]) -> Callable[[], Any]:
    """The one way to build envs: the ``env`` node's ``_target_`` with its fields as keywords.

    Used by the collector workers, training's evaluation, ``rlgrasp-eval`` and the benchmarks. The
    partial is picklable, so it travels to spawned workers and Ray actors as it is; ``_convert_``
    makes the keywords (``randomization`` as a preset name or a mapping) plain Python values.
    """
    return instantiate(env_cfg, _partial_=True, _convert_="all")


# --- validation of a training config (before any worker starts) -------------------------------
def _positive(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0


def _train_problems(cfg: Any) -> list[str]:
    """Each bad value of a composed training config as ``key=value: what is allowed``."""
    c, a, m, e, k = cfg.collector, cfg.algo, cfg.model, cfg.eval, cfg.checkpoint
    workers = 1 if c.backend == "single" or c.num_workers == 0 else c.num_workers
    batch = workers * c.envs_per_worker * c.steps_per_env
    checks = [
        ("total_frames", cfg.total_frames, cfg.total_frames > 0, "must be > 0"),
        ("time_budget_min", cfg.time_budget_min, cfg.time_budget_min is None or cfg.time_budget_min > 0,
         "must be > 0 or null"),
        ("collector.backend", c.backend, c.backend in ("process", "ray", "single"),
         "must be process, ray or single"),
        ("collector.num_workers", c.num_workers, c.num_workers >= 0, "must be >= 0 (0: in-process)"),
        ("collector.envs_per_worker", c.envs_per_worker, c.envs_per_worker >= 1, "must be >= 1"),
        ("collector.steps_per_env", c.steps_per_env, c.steps_per_env >= 1, "must be >= 1"),
        ("collector.torch_threads", c.torch_threads, c.torch_threads >= 1, "must be >= 1"),
        ("algo.epochs", a.epochs, a.epochs >= 1, "must be >= 1"),
        ("algo.minibatch_size", a.minibatch_size, 1 <= a.minibatch_size <= max(batch, 1),
         f"must be between 1 and the batch size ({batch:,} frames = workers x envs_per_worker x "
         "steps_per_env)"),
        ("algo.lr", a.lr, a.lr > 0, "must be > 0"),
        ("algo.gamma", a.gamma, 0 < a.gamma <= 1, "must be in (0, 1]"),
        ("algo.gae_lambda", a.gae_lambda, 0 <= a.gae_lambda <= 1, "must be in [0, 1]"),
        ("algo.clip_epsilon", a.clip_epsilon, a.clip_epsilon > 0, "must be > 0"),
        ("algo.max_grad_norm", a.max_grad_norm, a.max_grad_norm > 0, "must be > 0"),
        ("model.hidden_sizes", list(m.hidden_sizes), len(m.hidden_sizes) > 0 and all(
            _positive(h) for h in m.hidden_sizes), "must be a non-empty list of positive sizes"),
        ("model.activation", m.activation, m.activation in ("tanh", "relu", "elu"),
         "must be tanh, relu or elu"),
        ("eval.episodes", e.episodes, e.episodes >= 1, "must be >= 1"),
        ("eval.final_episodes", e.final_episodes, e.final_episodes is None or e.final_episodes >= 1,
         "must be >= 1 or null"),
        ("eval.num_envs", e.num_envs, e.num_envs >= 1, "must be >= 1"),
        ("checkpoint.keep_last", k.keep_last, k.keep_last >= 1, "must be >= 1"),
        ("checkpoint.interval_frames", k.interval_frames, k.interval_frames >= 0,
         "must be >= 0 (0: only at the end)"),
        ("logger.backend", cfg.logger.backend, cfg.logger.backend in ("tensorboard", "none"),
         "must be tensorboard or none"),
    ]
    return [f"{key}={value!r}: {allowed}" for key, value, ok, allowed in checks if not ok] + _device_problems(
        cfg.device
    )


def _device_problems(device: str) -> list[str]:
    import torch

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


def validate_train(cfg: Any) -> None:
    """Refuse a training config with a bad value: ``ConfigError`` naming the first (and how many
    more). The env's own keywords are checked by the env when the learner builds it, before workers."""
    if OmegaConf.is_config(cfg) and cfg.env.get("_target_") == EnvConfig._target_:
        try:
            OmegaConf.merge(OmegaConf.structured(EnvConfig), cfg.env)
        except Exception as exc:  # noqa: BLE001 - OmegaConf's validation errors
            raise ConfigError(f"env: {str(exc).splitlines()[0]}") from None
    problems = _train_problems(cfg)
    if problems:
        more = f" (and {len(problems) - 1} more: {'; '.join(problems[1:])})" if len(problems) > 1 else ""
        raise ConfigError(problems[0] + more)


class RunDirCheck(Callback):
    """Hydra callback (``configs/hydra/default.yaml``): an output directory that cannot be created
    ends the command with one line instead of Hydra's traceback from inside its job runner."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        _OUTPUT_SUBDIRS.clear()  # a new start in this process (tests run several): choose afresh
        self._check(config.hydra.run.dir)

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        self._check(config.hydra.sweep.dir)

    @staticmethod
    def _check(path: Any) -> None:
        import sys

        # Creates nothing: hydra.run.dir holds the time, so this resolution may name another second
        # than the one the job then creates; a directory made here would be left behind empty.
        target = Path(str(path)).absolute()
        existing = next(p for p in (target, *target.parents) if p.exists())
        problem = None
        if not existing.is_dir():
            problem = "Not a directory"
        elif not os.access(existing, os.W_OK | os.X_OK):
            problem = f"{existing} is not writable"
        if problem:
            print(f"error: cannot create the run directory {path}: {problem}", file=sys.stderr)
            sys.exit(2)
