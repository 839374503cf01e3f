"""The Hydra config tree composes, bad overrides fail at start naming the key, and the env schema
mirrors the env's constructor."""

from __future__ import annotations

import dataclasses
import inspect
import pickle
from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf
from omegaconf.errors import ConfigKeyError, ValidationError

from rlgrasp.config import CONFIG_DIR, EnvConfig
from rlgrasp.envs import PandaGraspEnv
from rlgrasp.envs.factory import env_factory

EXPERIMENTS = sorted(p.stem for p in (Path(CONFIG_DIR) / "experiment").glob("*.yaml"))


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_experiment_composes(experiment: str, train_cfg) -> None:
    cfg = train_cfg(f"experiment={experiment}")
    assert cfg.experiment_name == experiment
    assert cfg.algo.name == "ppo"
    assert cfg.env._target_ == "rlgrasp.envs.PandaGraspEnv"
    OmegaConf.to_container(cfg, resolve=True)  # every interpolation resolves


@pytest.mark.parametrize(
    "group",
    ["randomization=none", "randomization=wide", "collector=single", "logger=none", "debug=default"],
)
def test_group_options_compose(group: str, train_cfg) -> None:
    cfg = train_cfg(group)
    if group.startswith("randomization"):
        assert cfg.env.randomization == group.split("=")[1]
    if group in ("collector=single", "debug=default"):
        assert cfg.collector.backend == "single"


def test_grasp_ppo_defaults(train_cfg) -> None:
    cfg = train_cfg("experiment=grasp_ppo")
    assert cfg.env.randomization == "default"
    assert cfg.env.control_mode == "joint_delta"
    assert cfg.algo.gamma == pytest.approx(0.9)
    assert list(cfg.model.hidden_sizes) == [256, 256]
    assert cfg.algo.gae_every_epoch is False
    assert cfg.eval.final_episodes == 100


def test_env_schema_mirrors_the_constructor() -> None:
    """Every keyword of PandaGraspEnv, with the same default: a new one is a new EnvConfig field."""
    params = inspect.signature(PandaGraspEnv.__init__).parameters
    ctor = {k: p.default for k, p in params.items() if k != "self"}
    fields = [f.name for f in dataclasses.fields(EnvConfig) if f.name != "_target_"]
    schema = {name: getattr(EnvConfig(), name) for name in fields}
    assert schema == ctor


def test_env_factory_is_one_picklable_partial(train_cfg) -> None:
    cfg = train_cfg("env.ee_yaw=true", "env.randomization={preset:none,object_mass:[0.5,1.0]}")
    make_env = pickle.loads(pickle.dumps(env_factory(cfg.env)))
    assert make_env.keywords["ee_yaw"] is True
    assert make_env.keywords["randomization"] == {"preset": "none", "object_mass": [0.5, 1.0]}
    assert type(make_env.keywords["randomization"]) is dict  # plain values, not OmegaConf nodes
    env = make_env()
    try:
        assert env.action_space.shape == (5,)  # dx, dy, dz, dyaw, gripper
    finally:
        env.close()


@pytest.mark.parametrize(
    ("override", "error", "names"),
    [
        ("algo.lr=abc", ValidationError, ["algo.lr", "abc"]),
        ("algo.lrr=0.1", ConfigKeyError, ["lrr"]),
        ("total_frames=many", ValidationError, ["total_frames"]),
        ("collector.num_workers=1.5", ValidationError, ["collector.num_workers"]),
        ("collector=bogus", ConfigCompositionException, ["collector", "process", "single"]),
        ("env.ee_yaw=maybe", ValidationError, ["env.ee_yaw", "maybe"]),
        ("env.ee_yew=true", ConfigKeyError, ["ee_yew"]),
    ],
)
def test_bad_override_fails_naming_the_key(override: str, error: type, names: list[str], train_cfg) -> None:
    with pytest.raises((error, ConfigCompositionException)) as info:
        train_cfg(override)
    text = str(info.value) + str(info.value.__cause__ or "")
    for name in names:
        assert name in text, text
