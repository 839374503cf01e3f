"""Tasks as parts: reward terms declared in config, the goal tasks' gymnasium-robotics contract, a
user's own task and term from outside the package, and old configs read into today's shape."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from rlgrasp.compose import compose_train
from rlgrasp.envs import GraspEnv
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.tasks import TASKS, RewardConfigError, RewardTerms, goal_distance, task_name
from rlgrasp.legacy import nest_task
from rlgrasp.received import read_config

USER_CONFIGS = Path(__file__).resolve().parent / "user_configs"
GOAL_TASKS = ("pick_place", "push", "stack")


def _terms(**spec) -> RewardTerms:
    library = {"one": lambda task, r: 1.0, "half": lambda task, r, k=0.5: k}
    presets = {"both": {"terms": {"one": {"weight": 1.0}, "half": {"weight": 3.0}}, "normalize": True}}
    return RewardTerms(spec.pop("spec", "both"), presets, library, **spec)


def test_terms_sum_weighted_normalize_and_keep_episode_sums() -> None:
    terms = _terms()
    assert terms(None, {}) == pytest.approx((1.0 * 1.0 + 3.0 * 0.5) / 4.0)
    terms(None, {})
    assert terms.names == ["one", "half"]
    assert terms.episode_sums.tolist() == pytest.approx([2.0, 3.0])
    terms.reset()
    assert terms.episode_sums.tolist() == [0.0, 0.0]


def test_terms_reweighted_given_params_and_unnormalized() -> None:
    spec = {"terms": {"half": {"weight": 2.0, "k": 0.25}}, "normalize": False}
    assert _terms(spec=spec)(None, {}) == pytest.approx(0.5)
    assert _terms(weights={"half": 1.0})(None, {}) == pytest.approx((1.0 + 0.5) / 2.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"spec": "dense"}, "unknown reward 'dense' (env.task.reward); this task's term sets: both"),
        ({"spec": {"terms": {"three": {}}}}, "unknown reward term 'three' (env.task.reward.terms)"),
        ({"weights": {"won": 1.0}}, "unknown reward term 'won' (env.task.weights); terms: one, half"),
        ({"weights": {"one": math.inf}}, "env.task.reward.terms.one.weight must be a finite number, got inf"),
        ({"spec": {"terms": {"half": {"kk": 1}}}}, "env.task.reward.terms.half"),
        ({"spec": {"terms": {"one": {"weight": 0.0}}}}, "must sum to more than 0"),
        (
            {"spec": {"terms": {"x": {"_target_": "no.such.term"}}}},
            "env.task.reward.terms.x._target_='no.such.term' cannot be imported "
            "(no module 'no' is installed)",
        ),
        (
            {"spec": {"terms": {"x": {"_target_": "math.nothing"}}}},
            "env.task.reward.terms.x._target_='math.nothing' cannot be imported (math has no 'nothing')",
        ),
        (
            {"spec": {"terms": {"x": {"_target_": "math.pi"}}}},
            "env.task.reward.terms.x._target_='math.pi' is not callable",
        ),
    ],
)
def test_bad_terms_fail_in_one_line_naming_the_key(kwargs, message) -> None:
    with pytest.raises(RewardConfigError) as info:
        _terms(**kwargs)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_lift_dense_reward_is_its_terms_sum_and_logs_each_term() -> None:
    env = GraspEnv(randomization="none")
    env.reset(seed=3)
    total = 0.0
    for _ in range(10):
        _, reward, _, _, info = env.step(env.action_space.sample())
        total += reward
    # reach + grasp + 2 lift + success over their weights' sum, so the episode sums add up to the return
    assert float(info["reward_terms"].sum()) / 5.0 == pytest.approx(total, rel=1e-5)
    assert env.task.reward.names == ["reach", "grasp", "lift", "success"]
    env.close()


@pytest.mark.parametrize("task", GOAL_TASKS)
def test_goal_task_keeps_the_gymnasium_robotics_contract(task) -> None:
    env = GraspEnv(task=task, randomization="default")
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=1)
    assert set(obs) == {"observation", "achieved_goal", "desired_goal"}
    rng = np.random.default_rng(0)
    for _ in range(15):
        obs, reward, _, _, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        # the step's sparse reward is compute_reward's, which HER relabels with
        assert reward == env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        assert bool(info["is_success"]) == (reward > 0) or task == "stack"
    batch = np.stack([obs["achieved_goal"], obs["desired_goal"]])
    rewards = env.unwrapped.compute_reward(batch, batch[::-1], None)  # vectorized: two goals at once
    assert rewards.shape == (2,) and rewards[0] == rewards[1]
    assert env.unwrapped.compute_reward(batch, batch, None).tolist() == [1.0, 1.0]
    env.close()


def test_flat_goal_observation_is_the_dict_one_in_one_vector() -> None:
    flat = GraspEnv(task={"name": "pick_place", "observation": "flat"}, randomization="none")
    dict_env = GraspEnv(task="pick_place", randomization="none")
    vector, _ = flat.reset(seed=5)
    obs, _ = dict_env.reset(seed=5)
    np.testing.assert_array_equal(vector[flat.obs_slices["desired_goal"]], obs["desired_goal"])
    np.testing.assert_array_equal(vector[:-3], obs["observation"])
    flat.close(), dict_env.close()


@pytest.mark.parametrize("task", GOAL_TASKS)
def test_goals_lie_in_reach_apart_from_the_start_and_follow_the_seed(task) -> None:
    env = GraspEnv(task=task, randomization="default")
    goals = []
    for seed in range(6):
        obs, _ = env.reset(seed=seed)
        goal, start = obs["desired_goal"], obs["achieved_goal"]
        assert np.all(np.abs(goal[:2] - (0.6, 0.0)) <= 0.15 + 1e-6)
        assert 0.0 <= goal[2] <= 0.3 and goal_distance(goal, start) >= 0.05
        goals.append(goal)
    assert len({tuple(g) for g in goals}) == 6
    np.testing.assert_array_equal(env.reset(seed=2)[0]["desired_goal"], goals[2])
    env.close()


def test_pick_place_draws_goals_in_the_air_and_on_the_table() -> None:
    env = GraspEnv(task="pick_place", randomization="none")
    heights = [env.reset(seed=s)[0]["desired_goal"][2] - env.unwrapped.task.rest_z for s in range(30)]
    assert sum(h < 1e-9 for h in heights) >= 5 and sum(h > 0.02 for h in heights) >= 5
    env.close()


def test_push_pays_the_hand_behind_the_object_more_than_in_front() -> None:
    from rlgrasp.envs.tasks.goal import behind

    centre, goal = np.array([0.6, 0.0, 0.025]), np.array([0.7, 0.0, 0.025])
    readings = {"object_centre": centre, "desired_goal": goal}
    back = behind(None, {**readings, "grasp_pos": centre - [0.05, 0.0, 0.0]})
    front = behind(None, {**readings, "grasp_pos": centre + [0.05, 0.0, 0.0]})
    assert back == pytest.approx(1.0) and front < 0.6  # 1 - tanh(5 x 0.1 m)
    env = GraspEnv(task={"_target_": "rlgrasp.envs.tasks.PushTask", "reward": "dense"})
    assert env.task.reward.names == ["behind", "place", "place_fine", "success"]
    env.close()


def test_goal_marker_shows_in_renders_only() -> None:
    watched = GraspEnv(task="push", render_mode="rgb_array")
    watched.reset(seed=0)
    assert watched.scene.marker is not None
    trained = GraspEnv(task="push")
    trained.reset(seed=0)
    assert trained.scene.marker is None  # nothing a policy's camera could see
    watched.close(), trained.close()


def test_every_task_is_named_by_its_short_name_and_its_class() -> None:
    for name, cls in TASKS.items():
        assert task_name(name) == name
        assert task_name({"_target_": f"rlgrasp.envs.tasks.{cls.__name__}"}) == name
    assert task_name({"_target_": "tests.user_task.HighLiftTask"}) == "tests.user_task.HighLiftTask"


def test_a_users_task_and_term_from_outside_the_package() -> None:
    """docs/tasks.md's example: a class and a config file of the user's, no edit of rlgrasp."""
    cfg = compose_train(["experiment=smoke", f"hydra.searchpath=[file://{USER_CONFIGS}]", "task=high_lift"])
    env = env_factory(cfg.env)()
    env.reset(seed=0)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert env.task.reward.names == ["reach", "grasp", "lift", "success", "hand_height"]
    assert env.task.success_height == 0.15 and info["reward_terms"][-1] > 0
    env.close()
    own_term = {"terms": {"high": {"_target_": "tests.user_task.hand_height", "weight": 1.0, "target": 0.3}}}
    env = GraspEnv(task={"name": "lift", "reward": own_term})
    env.reset(seed=0)
    assert env.step(env.action_space.sample())[1] > 0
    env.close()


def test_old_flat_reward_keys_are_read_into_the_task() -> None:
    old = {"_target_": "rlgrasp.envs.PandaGraspEnv", "reward": "sparse", "reward_weights": None,
           "success_height": 0.07, "terminate_on_success": True, "objects": "cube"}  # fmt: skip
    env_cfg = read_config({"env": old}, "old.pt")["env"]
    assert env_cfg["task"] == {
        "_target_": "rlgrasp.envs.tasks.LiftTask",
        "reward": "sparse",
        "success_height": 0.07,
        "terminate_on_success": True,
    }
    assert "reward" not in env_cfg and nest_task(env_cfg) == env_cfg  # today's shape is left alone
    env = env_factory(env_cfg)()
    assert env.task.reward_name == "sparse" and env.task.terminate_on_success
    env.close()


def test_demonstrations_are_matched_on_the_task_and_its_reward() -> None:
    from rlgrasp.demos.dataset import task_reward

    assert task_reward(compose_train(["experiment=pick_place_sac_demos"]).env) == (
        "task=pick_place env.task.reward=dense"
    )
    assert (
        task_reward({"task": {"_target_": "rlgrasp.envs.tasks.PushTask"}})
        == "task=push env.task.reward=sparse"
    )
    assert task_reward({"reward": "sparse"}) == "task=lift env.task.reward=sparse"  # a recording of before


def test_a_camera_policy_reads_the_goal_beside_its_image_and_never_sees_the_marker() -> None:
    camera = {"mount": "wrist", "modality": "depth", "width": 32, "height": 32}
    env = GraspEnv(task="pick_place", camera=camera, render_mode="rgb_array", randomization="none")
    marker_in_view = 0
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        goal = obs["privileged"][env.obs_slices["desired_goal"]]
        np.testing.assert_array_equal(obs["state"][-3:], goal)  # proprioception, then the goal
        mount = env.robot.camera_mount()
        seen = env.camera.render(mount)["depth"]  # the marker drawn, as people's renders have it
        env.scene.set_marker_alpha(0.0)
        hidden = env.camera.render(mount)["depth"]
        env.scene.set_marker_alpha(1.0)
        np.testing.assert_array_equal(obs["depth"][-1], hidden[-1])  # the policy's image: no marker
        marker_in_view += int((seen != hidden).any())
    assert marker_in_view > 0  # the check above compared images that the marker would change
    env.close()


def test_received_files_may_name_exactly_the_registered_tasks() -> None:
    """received.py holds the tasks as strings (it must not import PyBullet): the two lists agree."""
    from rlgrasp.received import PARTS

    assert set(PARTS["task"]) == set(TASKS)
    for name, path in PARTS["task"].items():
        module, _, leaf = path.rpartition(".")
        assert leaf == TASKS[name].__name__ and module == "rlgrasp.envs.tasks"


def test_fine_goal_term_pays_for_precision_inside_the_success_radius() -> None:
    """The coarse term barely changes inside 5 cm; the fine one (scale 20) does: what keeps a
    learned policy at the goal rather than drifting to the radius's edge."""
    from rlgrasp.envs.tasks.goal import GoalTask, place

    goal = np.array([0.6, 0.0, 0.1])
    held = {"grasped": np.array([1.0]), "desired_goal": goal}
    near, edge = ({**held, "achieved_goal": goal + [d, 0.0, 0.0]} for d in (0.01, 0.045))
    fine = GoalTask.TERM_SETS["dense"]["terms"]["place_fine"]["scale"]
    assert place(None, near, scale=fine) - place(None, edge, scale=fine) > 0.4
    assert place(None, near) - place(None, edge) < 0.2


def test_stack_pays_more_for_letting_go_on_the_base_than_for_holding_there() -> None:
    """Success needs the fingers off the cube: the dense set must not pay more for holding it."""
    env = GraspEnv(task={"_target_": "rlgrasp.envs.tasks.StackTask", "reward": "dense"})
    task = env.task
    goal = np.array([0.6, 0.0, 0.075])
    base = {
        "desired_goal": goal,
        "achieved_goal": goal.copy(),
        "object_centre": goal.copy(),
        "base_moved": 0.0,
    }
    held = {**base, "grasped": np.array([1.0]), "grasp_pos": goal.copy()}
    released = {**base, "grasped": np.array([0.0]), "grasp_pos": goal + [0.0, 0.0, 0.06]}
    assert task.reward(task, released) > task.reward(task, held)
    env.close()
