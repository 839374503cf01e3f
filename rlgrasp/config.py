"""The run's config trees (training, evaluation, demonstrations, sweeps) and their registration with
Hydra. The checks of a training config's values are the training core's (``rlgrasp.train.validate``).

A part's schema lives beside its code and is registered here: the env's (``rlgrasp.envs.grasp_env
.EnvConfig`` with its parts' ``ControlConfig`` and ``SimConfig``), the models'
(``rlgrasp.models``), the collectors' (``rlgrasp.collector_schema``), the loggers'
(``rlgrasp.logger_schema``) and each algorithm's (its package: ``rlgrasp.algos.registry``). The YAML
files under ``configs/`` name these schemas in their defaults lists, so a typo, a wrong type or an
unknown key fails at start with Hydra's message naming the key, instead of deep inside a worker
process minutes later. Each default is written once, in its schema; the YAML files carry only what
differs from it. Training (``train.yaml``), evaluation (``eval.yaml``) and sweeps
(``sweep/<name>.yaml``) are three separate trees; ``rlgrasp.compose`` composes them outside a
command line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, OmegaConf

from rlgrasp.algos.registry import algorithms
from rlgrasp.collector_schema import CollectorConfig, RayCollectorConfig
from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.errors import ConfigError  # noqa: F401 - where the callers have always imported it from
from rlgrasp.logger_schema import LoggerConfig, MlflowLoggerConfig, WandbLoggerConfig
from rlgrasp.models.cnn import CNNConfig
from rlgrasp.models.mlp import MLPConfig
from rlgrasp.rundir import register_resolvers

#: The Hydra config tree (``configs/`` next to the package in a source checkout).
CONFIG_DIR = os.environ.get("RLGRASP_CONFIG_DIR", str(Path(__file__).resolve().parents[1] / "configs"))


# --- training ---------------------------------------------------------------------------------
# --- algorithms: each one's schema and checks are its package's (rlgrasp.algos.<name>.schema),
# found through rlgrasp.algos.registry; the flat keys of before are rlgrasp.legacy's.


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
    # The periodic evaluations in a process of their own (rlgrasp.train.evaluation.eval_process) while
    # training goes on; each result is logged at the frames of the weights it evaluated, and picked up
    # when the next one is due (so a sweep's pruner hears of it one interval later). false: in the
    # learner's process, training waits. The final evaluation runs in the learner's process, shared with the
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
    # Env keywords over the checkpoint's env config, e.g. env.sim.max_episode_steps=80 (as in training;
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
    for algo in algorithms().values():  # each algorithm's package holds its schema
        cs.store(group="algo", name=f"{algo.name}_schema", node=algo.schema_class())
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
