"""The env's seams: robot, control mode, task and observation parts are separate pieces."""

from __future__ import annotations

import numpy as np
import pytest

from rlgrasp.envs import GraspEnv
from rlgrasp.envs.control import EEDelta, JointDelta, JointTorque
from rlgrasp.envs.observation import PROPRIOCEPTION, ObservationLayout, Part, full_parts
from rlgrasp.envs.robot import ROBOTS, Panda, make_robot


def test_layout_slices_and_noise_touch_only_noisy_parts():
    layout = ObservationLayout([Part("a", 2), Part("flag", 1, noisy=False), Part("b", 3)])
    assert layout.slices == {"a": slice(0, 2), "flag": slice(2, 3), "b": slice(3, 6)}
    assert layout.noisy_size == 5
    vector = layout.assemble({"a": [1, 2], "flag": [1], "b": np.zeros(3)})
    layout.add_noise(vector, np.full(5, 0.5))
    assert vector.tolist() == [1.5, 2.5, 1.0, 0.5, 0.5, 0.5]
    assert layout.select(vector, ["b", "flag"]).tolist() == [0.5, 0.5, 0.5, 1.0]


def test_full_layout_is_sized_from_the_arm_and_the_action():
    parts = {p.name: p.size for p in full_parts(arm_dof=6, action_dim=4)}
    assert parts["arm_q"] == parts["arm_qd"] == 6 and parts["prev_action"] == 4
    assert set(PROPRIOCEPTION) <= set(parts)
    assert not any(name.startswith("object") for name in PROPRIOCEPTION)


def test_unknown_robot_names_the_valid_ones(make_env):
    with pytest.raises(ValueError, match="unknown robot 'ur5'; valid robots: panda"):
        make_env(robot="ur5")


class ShortPanda(Panda):
    """A stand-in for a new arm: another neutral pose, registered without touching the env."""

    neutral_pose = (0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.79)


def test_a_new_robot_is_a_class_and_a_registry_entry(monkeypatch):
    monkeypatch.setitem(ROBOTS, "short_panda", ShortPanda)
    env = GraspEnv(robot="short_panda", randomization="none", control={"mode": "joint_delta"})
    try:
        obs, _ = env.reset(seed=0)
        q = obs[env.obs_slices["arm_q"]]
        assert np.allclose(q, ShortPanda.neutral_pose, atol=1e-6)
        assert isinstance(env.control, JointDelta) and env.action_dim == 8
    finally:
        env.close()


@pytest.mark.parametrize(
    "mode, kind, dim",
    [("ee_delta", EEDelta, 4), ("joint_delta", JointDelta, 8), ("joint_torque", JointTorque, 8)],
)
def test_control_modes_size_the_action_from_the_robot(mode, kind, dim, make_env):
    env = make_env(control={"mode": mode})
    assert isinstance(env.control, kind) and env.action_space.shape == (dim,)


def test_make_robot_loads_a_model_file_override(make_env):
    env = make_env()
    robot = make_robot("panda", env.client, "franka_panda/panda.urdf")
    assert robot.arm_dof == 7 and robot.body != env.robot.body


@pytest.mark.parametrize("mode", ["ee_delta", "joint_delta"])
def test_a_step_reuses_readings_that_are_still_the_robots_state(mode, make_env):
    """The control target starts from the last observation's readings instead of reading the robot
    again: they must equal a fresh reading, and give the same target."""
    env = make_env(control={"mode": mode})
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(3):
        env.step(rng.uniform(-1, 1, env.action_dim).astype(np.float32))
        fresh = env.robot.readings()
        for name in ("arm_q", "grasp_pos"):
            assert np.array_equal(env._readings[name], fresh[name])
        action = rng.uniform(-1, 1, env.action_dim)
        assert np.array_equal(env.control.arm_target(action, env._readings), env.control.arm_target(action))


def test_the_cached_client_fails_after_close_as_pybullet_does():
    """Cached client-bound functions are dropped on disconnect: a call after close must not reach a
    client that later got the same id."""
    import pybullet

    from rlgrasp.envs.scene import Scene

    scene = Scene()
    client = scene.client
    assert client.getNumBodies() == 1  # the ground; the bound function is now cached
    scene.close()
    other = Scene()
    try:
        with pytest.raises(pybullet.error):
            client.getNumBodies()
    finally:
        other.close()


def test_an_env_config_of_before_the_parts_is_read_into_them() -> None:
    """Checkpoints written when the env took flat keywords (policies/*.pt) build today's env."""
    from rlgrasp.envs.factory import env_factory
    from rlgrasp.legacy import nest_env

    old = {
        "_target_": "rlgrasp.envs.PandaGraspEnv",
        "control_mode": "joint_delta",
        "ee_yaw": False,
        "max_episode_steps": 7,
        "render_width": 64,
        "visual": "default",
        "robot": "panda",
        "robot_urdf": "franka_panda/panda.urdf",
        "reward": "sparse",
    }
    new = nest_env(old)
    assert new["control"] == {"mode": "joint_delta", "ee_yaw": False}
    assert new["sim"] == {"max_episode_steps": 7, "visual": "default", "viewer": {"width": 64}}
    assert new["robot"] == {"name": "panda", "model": "franka_panda/panda.urdf"}
    assert new["task"]["reward"] == "sparse" and nest_env(new) == new
    env = env_factory(new)()
    try:
        env.reset(seed=0)
        ends = [env.step(env.action_space.sample())[3] for _ in range(7)]
        assert ends == [False] * 6 + [True] and env.action_space.shape == (8,)
    finally:
        env.close()
