"""The sweep schema (``configs/sweep/<name>.yaml``) and composing it with Hydra's compose API.

A sweep config is its own small tree, separate from the training config: the CLI sends
``sweep=<name>`` and ``sweep.*`` overrides here and everything else to the training config of each
trial, so one command line reads like a training command plus a search space.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra import compose, initialize_config_dir
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig

from rlgrasp.train.config import register_configs as register_train_configs

PRIMARY = "rlgrasp_sweep_primary"


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


def register_configs() -> None:
    """Register the training schemas, the sweep schema and the primary config the CLI composes."""
    register_train_configs()
    cs = ConfigStore.instance()
    cs.store(group="sweep", name="sweep_schema", node=SweepConfig)
    cs.store(name=PRIMARY, node={"defaults": [{"sweep": "smoke"}, "_self_"]})


def compose_sweep(config_dir: str | Path, overrides: list[str]) -> DictConfig:
    """The ``sweep`` node composed from ``configs/sweep/<name>.yaml`` and ``sweep.*`` overrides."""
    register_configs()
    with initialize_config_dir(config_dir=str(Path(config_dir).resolve()), version_base="1.3"):
        return compose(config_name=PRIMARY, overrides=list(overrides)).sweep


def compose_train(config_dir: str | Path, overrides: list[str]) -> DictConfig:
    """A training config as ``scripts/train.py`` would build it (without Hydra's run-time keys)."""
    register_train_configs()
    with initialize_config_dir(config_dir=str(Path(config_dir).resolve()), version_base="1.3"):
        return compose(config_name="train", overrides=list(overrides))
