"""The goal tasks' scripted experts (rlgrasp.envs.experts): each succeeds on most seeds under the
default randomization, reads the Dict and the flat observation alike, and is the evaluation's
``policy=scripted`` for its task.

Rates over a few seeds, not one episode. benchmarks/bench_expert.py --task <t> --episodes 200
--presets default (seeds 0-199, ee_yaw): pick_place 199/200, push 193/200, stack 175/200.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rlgrasp.compose import compose_eval
from rlgrasp.envs import GraspEnv, ScriptedExpert, expert_for
from rlgrasp.envs.experts import PickPlaceExpert, PushExpert, StackExpert, flat_observation
from rlgrasp.evaluation.cli import evaluate

EPISODES = 8
#: Successes of 8 (seeds 0-7, default preset) each expert must reach: all but about two.
AT_LEAST = {"pick_place": 7, "push": 7, "stack": 6}


def _successes(env, expert, seeds) -> int:
    successes = 0
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        expert.reset()
        for _ in range(env.sim.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
        successes += bool(info["is_success"])
    return successes


@pytest.mark.parametrize("task", sorted(AT_LEAST))
def test_each_goal_expert_succeeds_on_most_seeds(task: str) -> None:
    env = GraspEnv(task=task, control={"ee_yaw": True})
    try:
        assert _successes(env, expert_for(env), range(EPISODES)) >= AT_LEAST[task]
    finally:
        env.close()


@pytest.mark.parametrize("task", ["pick_place", "push", "stack"])
def test_the_dict_and_the_flat_observation_give_the_same_actions(task: str) -> None:
    """Dict mode's ``observation`` + ``desired_goal`` is the flat vector: the expert acts alike."""
    envs = [GraspEnv(task={"name": task, "observation": mode}) for mode in ("dict", "flat")]
    try:
        experts = [expert_for(env) for env in envs]
        observations = [env.reset(seed=3)[0] for env in envs]
        assert isinstance(observations[0], dict) and isinstance(observations[1], np.ndarray)
        for _ in range(20):
            actions = [expert(obs) for expert, obs in zip(experts, observations, strict=True)]
            np.testing.assert_array_equal(actions[0], actions[1])
            observations = [env.step(a)[0] for env, a in zip(envs, actions, strict=True)]
    finally:
        for env in envs:
            env.close()


def test_expert_for_picks_the_tasks_expert() -> None:
    kinds = {"lift": ScriptedExpert, "pick_place": PickPlaceExpert, "push": PushExpert, "stack": StackExpert}
    for task, kind in kinds.items():
        env = GraspEnv(task=task)
        try:
            assert type(expert_for(env)) is kind
        finally:
            env.close()
    env = GraspEnv(task="lift")
    try:
        assert type(ScriptedExpert.for_env(env)) is ScriptedExpert  # the lift expert, as before
    finally:
        env.close()


def test_flat_observation_reads_every_form_and_refuses_others() -> None:
    vector = np.arange(6, dtype=np.float32)
    goal = {"observation": vector[:-3], "achieved_goal": vector[:3], "desired_goal": vector[-3:]}
    np.testing.assert_array_equal(flat_observation(goal), vector)
    np.testing.assert_array_equal(flat_observation({"state": vector[:2], "privileged": vector}), vector)
    np.testing.assert_array_equal(flat_observation(vector), vector)
    with pytest.raises(ValueError, match="got a mapping of state"):
        flat_observation({"state": vector})


def test_scripted_evaluation_of_a_goal_task(tmp_path: Path) -> None:
    """``policy=scripted`` with ``env.task=push``: the push expert plays the Dict observation."""
    m = evaluate(
        compose_eval(
            [
                "policy=scripted",
                "+env.task=push",
                "episodes=4",
                "workers=1",
                "video=false",
                "plots=false",
                f"outputs_root={tmp_path}",
                "name=push",
            ]
        )
    )
    assert m["success_at_end"]["successes"] >= 3
    assert m["config"]["env"]["task"] in ("push", {"name": "push"})
