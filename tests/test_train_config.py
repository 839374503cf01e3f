"""The Hydra config tree composes, bad overrides fail at start naming the key, the env schema
mirrors the env's constructor, and every collector and logger option names a class that builds."""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pickle
from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf
from omegaconf.errors import ConfigKeyError, ValidationError

from rlgrasp.algos.registry import algorithms
from rlgrasp.config import CONFIG_DIR, ConfigError
from rlgrasp.envs import PandaGraspEnv
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.train.collection.collectors import (
    CollectorBackend,
    RayCollector,
    SingleCollector,
    collector_backend,
)
from rlgrasp.train.tracking.logger import ConsoleLogger
from rlgrasp.train.validate import validate_train

EXPERIMENTS = sorted(p.stem for p in (Path(CONFIG_DIR) / "experiment").glob("*.yaml"))


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_experiment_composes(experiment: str, train_cfg) -> None:
    cfg = train_cfg(f"experiment={experiment}")
    assert cfg.experiment_name == experiment
    # An experiment's name says its algorithm (grasp_sac_demos, grasp_vision_distill); PPO's say none.
    expected = next((name for name in algorithms() if f"_{name}" in experiment), "ppo")
    assert cfg.algo.name == expected
    assert cfg.algo._target_ == algorithms()[expected].target
    assert (cfg.env.get("camera") is not None) == ("vision" in experiment)
    # panda-gym's tasks (panda_*) are another package's env (env=gym), every other experiment rlgrasp's.
    gym = experiment.startswith("panda_")
    assert cfg.env._target_ == ("rlgrasp.envs.gym_env.make_gym_env" if gym else "rlgrasp.envs.PandaGraspEnv")
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
        assert cfg.collector._target_ == "rlgrasp.train.collection.collectors.SingleCollector"


def _options(group: str) -> list[str]:
    return sorted(p.stem for p in (Path(CONFIG_DIR) / group).glob("*.yaml"))


@pytest.mark.parametrize("collector", _options("collector"))
def test_each_collector_option_builds_its_backend(collector: str, train_cfg) -> None:
    """A backend is a class and a YAML file naming it; the schema still checks its keys."""
    cfg = train_cfg("experiment=smoke", f"collector={collector}")
    validate_train(cfg)
    backend = collector_backend(cfg.collector)
    assert isinstance(backend, CollectorBackend) and type(backend).__name__.lower().startswith(collector)
    workers = 1 if backend.in_process else cfg.collector.num_workers
    assert backend.frames_per_batch == workers * cfg.collector.envs_per_worker * cfg.collector.steps_per_env
    assert backend.collects_ahead == (cfg.collector.overlap and not backend.in_process)


@pytest.mark.parametrize("logger", _options("logger"))
def test_each_logger_option_names_a_logger_class(logger: str, train_cfg) -> None:
    cfg = train_cfg(f"logger={logger}")
    validate_train(cfg)
    module, _, name = cfg.logger._target_.rpartition(".")
    assert issubclass(getattr(importlib.import_module(module), name), ConsoleLogger)


def test_the_command_lines_of_the_string_backends_still_work(train_cfg) -> None:
    assert isinstance(collector_backend(train_cfg("collector=single").collector), SingleCollector)
    ray = collector_backend(train_cfg("collector=ray", "collector.ray.address=auto").collector)
    assert isinstance(ray, RayCollector) and ray.ray.address == "auto"
    assert train_cfg("logger=none").logger._target_ == "rlgrasp.train.tracking.logger.ConsoleLogger"
    assert train_cfg("logger=wandb", "logger.mode=offline").logger._target_.endswith("trackers.WandbLogger")
    assert collector_backend(train_cfg("collector.num_workers=4").collector).num_workers == 4


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            "collector._target_=rlgrasp.train.collection.collectors.Bogus",
            "collector._target_='rlgrasp.train.collection.collectors.Bogus' cannot be imported "
            "(rlgrasp.train.collection.collectors has no 'Bogus')",
        ),
        (
            "logger._target_=nowhere.Logger",
            "logger._target_='nowhere.Logger' cannot be imported (no module 'nowhere' is installed)",
        ),
        (  # a module that moved (rlgrasp.legacy.MOVED_MODULES), named in the user's own config
            "+algo.terms.x._target_=rlgrasp.train.rnd.RND",
            "algo.terms.x._target_='rlgrasp.train.rnd.RND' cannot be imported (rlgrasp.train has no 'rnd'); "
            "it moved: write 'rlgrasp.algos.ppo.rnd.RND'",
        ),
        ("collector.num_workers=-1", "collector.num_workers=-1: must be >= 0"),
    ],
)
def test_a_bad_backend_is_refused_in_one_line(override: str, message: str, train_cfg) -> None:
    with pytest.raises(ConfigError) as info:
        validate_train(train_cfg(override))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_an_unknown_algorithm_is_one_line_listing_the_registered_ones(train_cfg) -> None:
    names = sorted(algorithms())
    with pytest.raises(ConfigError) as refused:
        validate_train(train_cfg("algo.name=mine"))
    listed = ", ".join(names[:-1]) + " or " + names[-1]
    assert (
        str(refused.value) == f"algo.name='mine': must be {listed} (the algo group: algo={'|'.join(names)})"
    )


def test_the_core_names_no_algorithm() -> None:
    """Config validation, resume, the legacy loader, the reader of received files and the loop read the
    registry (rlgrasp.algos.registry): none of them names an algorithm."""
    root = Path(__file__).resolve().parents[1] / "rlgrasp"
    core = ["config.py", "received.py", "overrides.py", "legacy.py", "train/resume.py"]
    core += [f"train/{m}" for m in ("algorithm.py", "loop.py", "parts.py", "checkpoint.py")]
    for path in core:
        text = (root / path).read_text()
        for name in algorithms():
            assert f'"{name}"' not in text and f"'{name}'" not in text, f"{path} names {name}"


def test_grasp_ppo_defaults(train_cfg) -> None:
    cfg = train_cfg("experiment=grasp_ppo")
    assert cfg.env.randomization == "default"
    assert cfg.env.control.mode == "joint_delta"
    assert cfg.algo.loss.gamma == pytest.approx(0.9)
    assert list(cfg.model.hidden_sizes) == [256, 256]
    assert cfg.algo.loss.gae_every_epoch is False
    assert cfg.eval.final_episodes == 100


def test_env_schema_mirrors_the_constructor() -> None:
    """Every part PandaGraspEnv takes, with the same default: a new one is a new EnvConfig field. A
    part with a schema of its own (control, sim) defaults to None in the constructor, which builds
    that schema's defaults, and no field of it is declared again anywhere."""
    params = inspect.signature(PandaGraspEnv.__init__).parameters
    ctor = {k: p.default for k, p in params.items() if k != "self"}
    fields = [f.name for f in dataclasses.fields(EnvConfig) if f.name != "_target_"]
    assert fields == list(ctor) and len(ctor) <= 8
    default = EnvConfig()
    for name in fields:
        value = getattr(default, name)
        if dataclasses.is_dataclass(value):
            assert ctor[name] is None and value == type(value)()
        else:
            assert value == ctor[name], name


def test_env_factory_is_one_picklable_partial(train_cfg) -> None:
    cfg = train_cfg("env.control.ee_yaw=true", "env.randomization={preset:none,object_mass:[0.5,1.0]}")
    make_env = pickle.loads(pickle.dumps(env_factory(cfg.env)))
    assert make_env.keywords["control"]["ee_yaw"] is True
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
        ("algo.optim.lr=abc", ValidationError, ["algo.optim.lr", "abc"]),
        ("algo.lrr=0.1", ConfigKeyError, ["lrr"]),
        ("total_frames=many", ValidationError, ["total_frames"]),
        ("collector.num_workers=1.5", ValidationError, ["collector.num_workers"]),
        ("collector=bogus", ConfigCompositionException, ["collector", "process", "single"]),
        ("collector.ray.address=auto", ConfigKeyError, ["collector.ray"]),  # only collector=ray has it
        ("logger=mlflow logger.entity=me", ConfigKeyError, ["logger.entity"]),  # a W&B key
        ("env.control.ee_yaw=maybe", ValidationError, ["env.control.ee_yaw", "maybe"]),
        ("env.ee_yew=true", ConfigKeyError, ["ee_yew"]),
    ],
)
def test_bad_override_fails_naming_the_key(override: str, error: type, names: list[str], train_cfg) -> None:
    with pytest.raises((error, ConfigCompositionException)) as info:
        train_cfg(*override.split())
    text = str(info.value) + str(info.value.__cause__ or "")
    for name in names:
        assert name in text, text


def test_progress_line_shows_a_spent_time_budget_as_zero_left() -> None:
    from rlgrasp.train.tracking.logger import progress_line

    line = progress_line(100, 1000, 50.0, None, None, None, eta_s=-7.5)
    assert line.endswith("ETA 0:00:00")


def test_a_target_whose_module_lacks_a_package_names_that_package(train_cfg, tmp_path, monkeypatch) -> None:
    """A user's module that imports a package not installed is refused naming the package, not as a
    name its parent package lacks."""
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "__init__.py").write_text("")
    (tmp_path / "mine" / "loggers.py").write_text("import a_package_nobody_installed\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError) as info:
        validate_train(train_cfg("logger._target_=mine.loggers.MyLogger"))
    assert str(info.value) == (
        "logger._target_='mine.loggers.MyLogger' cannot be imported (importing mine.loggers failed "
        "(ModuleNotFoundError: No module named 'a_package_nobody_installed'))"
    )
