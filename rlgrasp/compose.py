"""Composing the Hydra configs outside a command line: what tests, sweeps and tools use to get the
config an entry point would build from the same overrides."""

from __future__ import annotations

from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from rlgrasp.config import CONFIG_DIR, SWEEP_PRIMARY, register_configs


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
