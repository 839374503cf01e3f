"""The Panda grasp environment: API conformance, determinism, randomization, control, bad input."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pybullet
import pytest
from gymnasium.utils.env_checker import check_env

import rlgrasp
from rlgrasp.envs import CONTROL_MODES, PandaGraspEnv, Randomizer, ScriptedExpert


@pytest.mark.parametrize("mode", CONTROL_MODES)
def test_gymnasium_check_env_passes(mode, make_env):
    env = make_env(
        render_mode="rgb_array", control={"mode": mode}, sim={"viewer": {"width": 64, "height": 48}}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # infinite observation bounds are deliberate
        check_env(env)


def test_registered_ids_make_the_env():
    for env_id in (rlgrasp.ENV_ID, "rlgrasp.envs:rlgrasp/PandaGrasp-v0"):
        env = gym.make(env_id, randomization="none")
        assert isinstance(env.unwrapped, PandaGraspEnv)
        env.close()


def test_torchrl_env_specs_and_info_keys():
    """The env as the collector workers build it passes TorchRL's spec check, info keys included."""
    import functools

    from torchrl.envs.utils import check_env_specs

    from rlgrasp.train.collection.collect import make_batched_env

    make_env = functools.partial(PandaGraspEnv, randomization="default", objects="primitives")
    env = make_batched_env(make_env, 2, base_seed=0, episode_stats=False, seed_torch=False)
    check_env_specs(env)
    rollout = env.rollout(3)
    assert rollout["next", "is_success"].dtype.is_floating_point is False
    assert rollout["next", "lift_height"].shape == (2, 3)
    env.close()


def _rollout(env, seed, actions):
    obs, info = env.reset(seed=seed)
    trace = [obs]
    for a in actions:
        obs, reward, *_ = env.step(a)
        trace.append(np.append(obs, reward))
    return trace, info["randomization"]


def test_same_seed_same_episode_bit_for_bit(make_env):
    env_a, env_b = make_env(randomization="default"), make_env(randomization="default")
    actions = np.random.default_rng(0).uniform(-1, 1, (30, env_a.action_dim)).astype(np.float32)
    trace_a, dr_a = _rollout(env_a, 7, actions)
    _rollout(env_a, 8, actions)  # a different episode in between must not leak into the next
    trace_b, dr_b = _rollout(env_b, 7, actions)
    trace_c, _ = _rollout(env_a, 7, actions)
    assert dr_a == dr_b
    for x, y, z in zip(trace_a, trace_b, trace_c):
        np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(x, z)
    trace_d, dr_d = _rollout(env_b, 9, actions)
    assert dr_d != dr_a and not np.array_equal(trace_d[0], trace_a[0])


def test_drawn_randomization_is_what_pybullet_simulates(make_env):
    env = make_env(randomization="wide")
    for seed in range(3):
        _, info = env.reset(seed=seed)
        dr = info["randomization"]
        c, body = env.client, env.scene.object
        dyn = c.getDynamicsInfo(body, -1)
        assert dyn[0] == pytest.approx(dr["object_mass"])
        assert dyn[1] == pytest.approx(dr["object_lateral_friction"])
        assert dyn[5] == pytest.approx(dr["object_restitution"])
        assert dyn[6] == pytest.approx(dr["object_rolling_friction"])
        assert dyn[7] == pytest.approx(dr["object_spinning_friction"])
        finger = c.getDynamicsInfo(env.robot.body, env.robot.finger_links[0])
        assert finger[1] == pytest.approx(dr["finger_friction"])
        assert env.robot.finger_force == pytest.approx(dr["finger_force"])
        assert c.getPhysicsEngineParameters()["gravityAccelerationZ"] == pytest.approx(dr["gravity_z"])
        # the cube is built at the drawn size: it rests at half its edge
        (x, y, z), quat = c.getBasePositionAndOrientation(body)
        assert z == pytest.approx(0.025 * dr["object_size_scale"], abs=1e-6)
        assert x == pytest.approx(0.6 + dr["object_x"]) and y == pytest.approx(dr["object_y"])
        assert c.getEulerFromQuaternion(quat)[2] == pytest.approx(dr["object_yaw"], abs=1e-6)


def test_presets_differ_in_what_they_randomize():
    rng = np.random.default_rng(0)
    none = [Randomizer("none").sample(rng) for _ in range(20)]
    default = [Randomizer("default").sample(rng) for _ in range(20)]
    assert len({d["object_mass"] for d in none}) == 1
    assert len({d["object_mass"] for d in default}) == 20
    assert len({d["object_x"] for d in none}) == 20  # the task's own pose variation stays
    wide = Randomizer("wide").ranges["object_mass"]
    base = Randomizer("default").ranges["object_mass"]
    assert wide.high - wide.low > base.high - base.low


def test_explicit_ranges_override_a_preset():
    r = Randomizer({"preset": "default", "object_mass": [0.9, 1.0], "action_delay": 2})
    values = r.sample(np.random.default_rng(1))
    assert 0.9 <= values["object_mass"] <= 1.0
    assert values["action_delay"] == 2


def _grasp_pos(env):
    return env.robot.grasp_point()[0]


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_ee_delta_moves_the_grasp_point_as_commanded(axis, make_env):
    env = make_env(randomization="none", control={"mode": "ee_delta"})
    for sign in (1.0, -1.0):
        env.reset(seed=0)
        start = _grasp_pos(env)
        action = np.zeros(4, np.float32)
        action[axis], action[-1] = sign, 1.0
        for _ in range(3):
            env.step(action)
        moved = _grasp_pos(env) - start
        assert sign * moved[axis] > 0.05  # 3 steps x 4 cm, minus tracking lag
        others = np.delete(moved, axis)
        assert np.all(np.abs(others) < 0.25 * abs(moved[axis]))


def test_ee_delta_keeps_fingertips_above_the_ground(make_env):
    env = make_env(randomization="none", control={"mode": "ee_delta"})
    env.reset(seed=3)
    env.scene.client.resetBasePositionAndOrientation(env.scene.object, [0.2, 0.6, 0.025], [0, 0, 0, 1])
    for _ in range(15):
        env.step(np.array([0, 0, -1, 1], np.float32))
    assert _grasp_pos(env)[2] > 0.0


def test_joint_delta_moves_the_commanded_joint(make_env):
    env = make_env(randomization="none", control={"mode": "joint_delta"})
    env.reset(seed=0)
    q0 = env.robot.joint_state()[0]
    action = np.zeros(8, np.float32)
    action[0], action[-1] = 1.0, 1.0
    for _ in range(3):
        env.step(action)
    dq = env.robot.joint_state()[0] - q0
    assert dq[0] > 0.1 and np.all(np.abs(dq[1:]) < 0.05)


def test_finger_width_follows_the_absolute_target(make_env):
    env = make_env(randomization="none")
    obs, _ = env.reset(seed=0)
    width = env.obs_slices["finger_width"]
    assert obs[width][0] == pytest.approx(0.08, abs=1e-3)
    for _ in range(5):
        obs, *_ = env.step(np.array([0, 0, 0, 0.0], np.float32))  # half open
    assert obs[width][0] == pytest.approx(0.04, abs=5e-3)


def test_torque_mode_with_gravity_compensation_holds_still(make_env):
    zero = np.zeros(8, np.float32)
    zero[-1] = 1.0
    drift = {}
    for compensate in (True, False):
        env = make_env(
            randomization="none", control={"mode": "joint_torque", "gravity_compensation": compensate}
        )
        env.reset(seed=0)
        q0 = env.robot.joint_state()[0]
        for _ in range(20):
            env.step(zero)
        drift[compensate] = np.abs(env.robot.joint_state()[0] - q0).max()
    assert drift[True] < 0.01
    assert drift[False] > 0.1  # without compensation the arm falls: the check can fail


def test_torque_mode_applies_commanded_torque(make_env):
    env = make_env(randomization="none", control={"mode": "joint_torque"})
    env.reset(seed=0)
    q0 = env.robot.joint_state()[0]
    action = np.zeros(8, np.float32)
    action[0], action[-1] = 0.5, 1.0
    env.step(action)
    assert env.robot.joint_state()[0][0] - q0[0] > 0.01


def test_reward_is_dense_staged_and_at_most_one(make_env):
    env = make_env(randomization="none")
    expert = ScriptedExpert(env.obs_slices)
    obs, _ = env.reset(seed=1)
    rewards, successes = [], []
    for _ in range(50):
        obs, reward, terminated, truncated, info = env.step(expert(obs))
        rewards.append(reward)
        successes.append(bool(info["is_success"]))
    assert truncated and not terminated
    assert all(0.0 <= r <= 1.0 for r in rewards)
    assert any(successes)
    # on success every stage pays: grasp + lift + success = 4/5 of the weight, plus most of reach
    assert all(r > 0.95 for r, ok in zip(rewards, successes) if ok)
    assert rewards[0] < 0.3  # far from the object, no grasp: only the reach term


def test_sparse_reward_and_terminate_on_success(make_env):
    task = {"name": "lift", "reward": "sparse", "terminate_on_success": True}
    env = make_env(randomization="none", task=task)
    expert = ScriptedExpert(env.obs_slices)
    obs, _ = env.reset(seed=2)
    steps = 0
    terminated = truncated = False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(expert(obs))
        assert reward == float(info["is_success"])
        steps += 1
    assert terminated and info["is_success"] and steps < 50


@pytest.mark.parametrize("terminate_on_success", [False, True])
def test_episode_info_comes_at_reset_and_at_the_last_step_only(terminate_on_success, make_env):
    env = make_env(
        randomization="default",
        task={"name": "lift", "terminate_on_success": terminate_on_success},
        sim={"max_episode_steps": 40},
    )
    expert = ScriptedExpert(env.obs_slices)
    episode_keys = {"object", "object_extents", "randomization"}
    obs, first = env.reset(seed=2)
    infos, done = [], False
    while not done:
        obs, _, terminated, truncated, info = env.step(expert(obs))
        infos.append(info)
        done = terminated or truncated
    assert episode_keys <= set(first) and episode_keys <= set(infos[-1])
    assert infos[-1]["randomization"] == first["randomization"] and infos[-1]["object"] == first["object"]
    assert all(not episode_keys & set(i) for i in infos[:-1]) and len(infos) > 1
    assert all({"is_success", "grasped", "lift_height", "object_tilt"} <= set(i) for i in infos)


def test_scripted_expert_lifts_under_default_randomization(make_env):
    env = make_env(randomization="default")
    expert = ScriptedExpert(env.obs_slices)
    successes = 0
    for seed in range(12):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        for _ in range(50):
            obs, _, _, _, info = env.step(expert(obs))
        successes += bool(info["is_success"])
    assert successes >= 10


def test_rgb_render_has_the_configured_size(make_env):
    env = make_env(render_mode="rgb_array", sim={"viewer": {"width": 80, "height": 60}})
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (60, 80, 3) and frame.dtype == np.uint8 and frame.std() > 0


# --- bad input -------------------------------------------------------------------------------


def test_unknown_control_mode_names_the_valid_ones():
    with pytest.raises(ValueError, match="'ee_velocity'.*ee_delta, joint_delta, joint_torque"):
        PandaGraspEnv(control={"mode": "ee_velocity"})


def test_unknown_randomization_parameter_or_preset():
    with pytest.raises(ValueError, match="'object_colour'.*object_mass"):
        PandaGraspEnv(randomization={"object_colour": [0, 1]})
    with pytest.raises(ValueError, match="'extreme'.*none, default, wide"):
        PandaGraspEnv(randomization="extreme")


@pytest.mark.parametrize(
    "ranges, match",
    [
        ({"object_mass": [0.5, 0.1]}, "'object_mass'.*greater than"),
        ({"object_mass": [-0.1, 0.2]}, "'object_mass'.*outside"),
        ({"object_lateral_friction": -0.5}, "'object_lateral_friction'.*outside"),
        ({"finger_friction": [math.nan, 1.0]}, "'finger_friction'.*finite"),
        ({"object_mass": {"low": 0.1}}, "'object_mass'.*'low', 'high'"),
    ],
)
def test_bad_ranges_name_the_parameter(ranges, match):
    with pytest.raises(ValueError, match=match):
        Randomizer(ranges)


def test_non_finite_action_is_refused(make_env):
    env = make_env(randomization="none")
    env.reset(seed=0)
    state = env.client.saveState()
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0, 0, 1], np.float32))
    # nothing was simulated: the world is where it was
    obs_after = env._observe()[0]
    env.client.restoreState(state)
    np.testing.assert_array_equal(obs_after, env._observe()[0])


def test_missing_model_file_names_the_path():
    with pytest.raises(FileNotFoundError, match="no_such_cube.urdf"):
        PandaGraspEnv(objects={"paths": ["no_such_cube.urdf"]})
    with pytest.raises(FileNotFoundError, match="env.robot.model: .*/tmp/missing/panda.urdf"):
        PandaGraspEnv(robot={"name": "panda", "model": "/tmp/missing/panda.urdf"})


def test_pybullet_clients_are_private(make_env):
    a, b = make_env(randomization="none"), make_env(randomization="none")
    assert a.client._client != b.client._client
    a.reset(seed=0)
    b.reset(seed=0)
    a.step(np.array([1, 0, 0, 1], np.float32))
    assert not np.allclose(_grasp_pos(a), _grasp_pos(b))
    assert pybullet.isConnected(a.client._client)
