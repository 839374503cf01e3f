"""Any gymnasium env as the trainer's target (``env=gym``, ``rlgrasp.envs.gym_env``): panda-gym's
PandaReach-v3 built flat and as its Dict, gymnasium's own checker on the adapted env, HER relabelling with
the env's own ``compute_reward``, a short SAC+HER run whose checkpoint rlgrasp-eval's loader reads back,
what a received file's ``env.id`` may import, and each bad input in one line naming its key.

The tests that build a panda-gym env skip without it (``pip install -e ".[panda]"``); the bad input
that needs none runs on gymnasium's own envs."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.algos.sac.her import goal_layout
from rlgrasp.config import ConfigError
from rlgrasp.envs.factory import env_factory, episode_steps
from rlgrasp.envs.gym_env import OBSERVATIONS, TARGET, make_gym_env
from rlgrasp.policy_file import load_checkpoint, policy_from_checkpoint
from rlgrasp.received import ReceivedError, read_config
from rlgrasp.train.loop import train
from rlgrasp.train.parts import build_parts
from rlgrasp.train.validate import validate_train
from tests.helpers import our_lines, run_entry
from tests.standins import PENDULUM_DICT

REACH = "panda_gym:PandaReach-v3"
#: env=gym with a state learner, before the case's keys.
GYM = ["env=gym", "algo=sac", "logger=none"]


@pytest.fixture
def panda() -> Any:
    """panda-gym, or the test skips (an optional extra: pip install -e ".[panda]")."""
    return pytest.importorskip("panda_gym")


def test_reach_flat_is_its_dict_with_the_goals_last(panda: Any) -> None:
    """The flat vector holds the Dict's values, the goals last, where ``obs_slices`` say; ``info``
    keeps ``is_success`` as a bool; the reward is the env's own ``compute_reward``."""
    flat, as_dict = make_gym_env(REACH), make_gym_env(REACH, observation="dict")
    obs, info = flat.reset(seed=3)
    dict_obs, _ = as_dict.reset(seed=3)
    slices = flat.unwrapped.obs_slices
    assert list(slices) == ["observation", "achieved_goal", "desired_goal"]
    assert slices["desired_goal"] == slice(9, 12) and flat.observation_space.shape == (12,)
    assert obs.dtype == np.float32 and flat.observation_space.contains(obs)
    for key, where in slices.items():
        np.testing.assert_array_equal(obs[where], dict_obs[key])
    assert info == {"is_success": False} and as_dict.observation_space == as_dict.env.observation_space
    obs, reward, _, _, info = flat.step(flat.action_space.sample())
    assert set(info) == {"is_success"} and isinstance(info["is_success"], bool)
    paid = flat.compute_reward(obs[slices["achieved_goal"]], obs[slices["desired_goal"]], info)
    assert reward == float(paid) and reward in (-1.0, 0.0)  # panda-gym's sparse reward
    assert flat.max_episode_steps == 50 == episode_steps(OmegaConf.create({"_target_": TARGET, "id": REACH}))
    flat.close()
    as_dict.close()


@pytest.mark.parametrize("observation", OBSERVATIONS)
def test_gymnasiums_checker_passes_on_the_adapted_env(panda: Any, observation: str) -> None:
    env = make_gym_env(REACH, observation=observation)
    check_env(env, skip_render_check=True)
    env.close()


def test_her_relabels_with_the_envs_own_reward_and_scale(panda: Any) -> None:
    """The goal slices of the flat vector, and a goal paid as panda-gym pays it (-1 beyond 5 cm, 0
    within), vectorized over the minibatch's rows."""
    layout = goal_layout(env_factory({"_target_": TARGET, "id": REACH}))
    assert (layout.achieved, layout.desired, layout.size) == (slice(6, 9), slice(9, 12), 3)
    achieved = torch.zeros(3, 3)
    desired = torch.tensor([[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.0, 0.2, 0.0]])
    assert layout.reward(achieved, desired).tolist() == [[0.0], [0.0], [-1.0]]


@pytest.mark.full
def test_a_short_sac_her_run_on_reach_writes_a_checkpoint_evaluation_reads(panda: Any, train_cfg) -> None:
    """SAC with HER on PandaReach-v3, in-process, a few hundred frames: it trains, relabels, and its
    checkpoint (an env=gym config) is read back as received data and gives a policy of the env's sizes."""
    cfg = train_cfg(
        *GYM,
        f"env.id={REACH}",
        "algo.her.enabled=true",
        "collector=single",
        "collector.envs_per_worker=2",
        "collector.steps_per_env=50",
        "total_frames=400",
        "algo.replay.learning_starts=200",
        "algo.optim.batch_size=64",
        "model.hidden_sizes=[32,32]",
        "algo.critic.hidden_sizes=[32,32]",
        "eval.interval_frames=0",
        "eval.episodes=2",
        "eval.final_episodes=2",
        "eval.num_envs=2",
    )
    success = train(cfg)
    assert 0.0 <= success <= 1.0
    state = load_checkpoint(Path(cfg.paths.output_dir) / "checkpoints" / "last.pt")
    assert state["config"]["env"] == {
        "_target_": TARGET,
        "id": REACH,
        "observation": "flat",
        "max_episode_steps": None,
    }
    assert state["updates"] > 0 and state["spec"]["obs_dim"] == 12
    policy = policy_from_checkpoint(state)
    env = make_gym_env(REACH)
    obs, _ = env.reset(seed=0)
    with torch.no_grad():
        action = policy(TensorDict({"observation": torch.as_tensor(obs)[None]}, [1]))["action"]
    assert action.shape == (1, 3) and env.action_space.contains(action[0].numpy())
    env.close()


def test_a_received_gym_config_may_import_only_panda_gym_or_the_users_module() -> None:
    """A file's env.id would import its module when the env is built: panda_gym (an extra's) passes, any
    other only where the user's own config's env.id names the same module; an id without one passes."""
    env = {"_target_": TARGET, "id": REACH, "observation": "flat", "max_episode_steps": None}
    assert read_config({"env": env}, "f")["env"] == env
    assert read_config({"env": {**env, "id": "Pendulum-v1"}}, "f")["env"]["id"] == "Pendulum-v1"
    foreign = {"env": {**env, "id": "antigravity:Fly-v0"}}
    with pytest.raises(ReceivedError) as refused:
        read_config(foreign, "f")
    assert "would import the module 'antigravity'" in str(refused.value) and "\n" not in str(refused.value)
    mine = {"env": {"_target_": TARGET, "id": "antigravity:Other-v0"}}
    assert read_config(foreign, "f", user=mine)["env"]["id"] == "antigravity:Fly-v0"
    with pytest.raises(ReceivedError, match="not a gymnasium id"):
        read_config({"env": {**env, "id": 3}}, "f")


BAD = [
    ([], "env.id: required with env=gym"),
    (["env.id=Nope-v0"], "env.id='Nope-v0': no gymnasium env 'Nope-v0' is registered"),
    (["env.id=no_such_module:Nope-v0"], "env.id='no_such_module:Nope-v0': the module no_such_module is not"),
    (["env.id=Pendulum-v1", "env.observation=image"], "env.observation='image': must be flat or dict"),
    (["env.id=Pendulum-v1", "env.max_episode_steps=0"], "env.max_episode_steps=0: must be >= 1, or null"),
    (["env.id=Pendulum-v1", "+env.nope=1"], "unexpected keyword argument 'nope'"),
    (["env.id=CartPole-v1"], "env.id='CartPole-v1': its actions are a Discrete"),
    (
        ["env.id=Pendulum-v1", "algo.her.enabled=true"],
        "algo.her.enabled=true: env.id='Pendulum-v1' observes a Box, without goals",
    ),
    (
        [f"env.id=tests.standins:{PENDULUM_DICT}", "algo.her.enabled=true"],
        "observes a Dict of state, without achieved_goal and desired_goal",
    ),
]


@pytest.mark.parametrize(("keys", "message"), BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_bad_input_is_one_line_naming_the_key(keys: list[str], message: str, train_cfg) -> None:
    with pytest.raises(ConfigError) as refused:
        validate_train(train_cfg(*GYM, *keys))
    assert message in str(refused.value) and "\n" not in str(refused.value), str(refused.value)


def test_a_missing_panda_gym_names_its_extra(train_cfg, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "panda_gym", None)  # as if not installed: its import fails
    with pytest.raises(ConfigError) as refused:
        validate_train(train_cfg(*GYM, f"env.id={REACH}"))
    assert str(refused.value) == (
        f"env.id='{REACH}': the module panda_gym is not installed (pip install -e \".[panda]\")"
    )


def test_an_id_another_package_registers_needs_its_module(train_cfg) -> None:
    """Registered here because this process imported its module, it would be unknown in a worker."""
    with pytest.raises(ConfigError) as refused:
        validate_train(train_cfg(*GYM, f"env.id={PENDULUM_DICT}"))
    assert f"name the module first, env.id=tests:{PENDULUM_DICT}" in str(refused.value)


def test_a_dict_observation_with_a_learner_of_one_vector_names_env_observation(panda: Any, train_cfg) -> None:
    with pytest.raises(ConfigError) as refused:
        build_parts(train_cfg(*GYM, f"env.id={REACH}", "env.observation=dict"))
    assert str(refused.value).startswith("env.observation=dict: the env observes a Dict (")
    assert "set env.observation=flat" in str(refused.value)


def test_the_train_script_refuses_in_one_line(tmp_path: Path, capsys) -> None:
    """Through scripts/train.py: an unknown id, and one of rlgrasp's own env parts with env=gym (a
    group env=grasp brings), each one line and no run left behind."""
    for args, message in (
        (["env.id=Nope-v0"], "error: env.id='Nope-v0': no gymnasium env"),
        (["env.id=Pendulum-v1", "task=push"], "error: task=push: a part of rlgrasp's own env (env=grasp)"),
    ):
        code = run_entry("train", [*GYM, *args, f"paths.root_dir={tmp_path}"], tmp_path)
        shown = capsys.readouterr()
        lines = [ln for ln in our_lines(shown.out + shown.err) if "error" in ln.lower()]
        assert code != 0 and len(lines) == 1 and message in lines[0], shown
        assert "Traceback" not in shown.out + shown.err
    assert not (tmp_path / "outputs").exists()
