"""The Hydra config tree composes, and bad overrides fail at start naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf
from omegaconf.errors import ConfigKeyError, ValidationError

from rlgrasp.train.config import register_configs

CONFIG_DIR = str(Path(__file__).resolve().parents[1] / "configs")
EXPERIMENTS = sorted(p.stem for p in (Path(CONFIG_DIR) / "experiment").glob("*.yaml"))


def _compose(overrides: list[str]):
    register_configs()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(config_name="train", overrides=overrides)


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_experiment_composes(experiment: str) -> None:
    cfg = _compose([f"experiment={experiment}", "paths.output_dir=/tmp/x"])
    assert cfg.experiment_name == experiment
    assert cfg.algo.name == "ppo"
    assert cfg.env.factory == "rlgrasp.envs:make_torchrl_env"
    OmegaConf.to_container(cfg, resolve=True)  # every interpolation resolves


@pytest.mark.parametrize(
    "group",
    [
        "randomization=none",
        "randomization=wide",
        "collector=single",
        "logger=none",
        "debug=default",
        "env=pendulum",
    ],
)
def test_group_options_compose(group: str) -> None:
    cfg = _compose([group, "paths.output_dir=/tmp/x"])
    if group.startswith("randomization"):
        assert cfg.env.randomization == group.split("=")[1]
    if group in ("collector=single", "debug=default"):
        assert cfg.collector.backend == "single"


def test_grasp_ppo_defaults() -> None:
    cfg = _compose(["experiment=grasp_ppo"])
    assert cfg.env.randomization == "default"
    assert cfg.env.control_mode == "joint_delta"
    assert cfg.algo.gamma == pytest.approx(0.9)
    assert list(cfg.model.hidden_sizes) == [256, 256]
    assert cfg.algo.gae_every_epoch is False
    assert cfg.eval.final_episodes == 100


@pytest.mark.parametrize(
    ("override", "error", "names"),
    [
        ("algo.lr=abc", ValidationError, ["algo.lr", "abc"]),
        ("algo.lrr=0.1", ConfigKeyError, ["lrr"]),
        ("total_frames=many", ValidationError, ["total_frames"]),
        ("collector.num_workers=1.5", ValidationError, ["collector.num_workers"]),
        ("collector=bogus", ConfigCompositionException, ["collector", "process", "single"]),
    ],
)
def test_bad_override_fails_naming_the_key(override: str, error: type, names: list[str]) -> None:
    with pytest.raises((error, ConfigCompositionException)) as info:
        _compose([override])
    text = str(info.value) + str(info.value.__cause__ or "")
    for name in names:
        assert name in text, text
