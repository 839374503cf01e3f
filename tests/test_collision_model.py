"""The opt-in primitive collision model: which shapes the arm's links get, and what stays as it was."""

from __future__ import annotations

import pybullet
import pytest

from rlgrasp.envs import ScriptedExpert
from rlgrasp.envs.collision_model import PRIMITIVES, collision_variant

PRIMITIVE_LINKS = set(PRIMITIVES["panda"])


def _shapes(env) -> dict[str, set[int]]:
    """Link name -> the geometry types of its collision shapes."""
    c, robot = env.client, env.robot
    return {
        name: {shape[2] for shape in c.getCollisionShapeData(robot.body, j)}
        for j, name in robot.link_names.items()
    }


def test_primitive_model_replaces_only_the_hand_and_finger_meshes(make_env):
    mesh, primitive = make_env(), make_env(sim={"collision_model": "primitive"})
    before, after = _shapes(mesh), _shapes(primitive)
    for name in PRIMITIVE_LINKS:
        assert before[name] == {pybullet.GEOM_MESH}
        assert after[name] <= {pybullet.GEOM_BOX, pybullet.GEOM_CAPSULE} and after[name]
    assert {n: s for n, s in after.items() if n not in PRIMITIVE_LINKS} == {
        n: s for n, s in before.items() if n not in PRIMITIVE_LINKS
    }
    for j in mesh.robot.link_names:  # the links weigh and move as before
        assert (
            mesh.client.getDynamicsInfo(mesh.robot.body, j)[:3]
            == primitive.client.getDynamicsInfo(primitive.robot.body, j)[:3]
        )


def test_primitive_model_with_a_wrist_camera_keeps_both_variants(make_env):
    env = make_env(camera={"mount": "wrist", "width": 16, "height": 16}, sim={"collision_model": "primitive"})
    assert _shapes(env)["panda_leftfinger"] <= {pybullet.GEOM_BOX}


def test_the_expert_still_lifts_the_cube_with_primitives(make_env):
    env = make_env(sim={"collision_model": "primitive"})
    expert = ScriptedExpert(env.obs_slices, action_dim=env.action_dim)
    successes = 0
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        for _ in range(env.sim.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
        successes += bool(info["is_success"])
    assert successes == 3


def test_bad_collision_model_fails_naming_the_valid_ones(make_env):
    with pytest.raises(ValueError, match="collision_model 'boxes'; valid: mesh, primitive"):
        make_env(sim={"collision_model": "boxes"})


def test_an_arm_without_primitive_shapes_is_refused(make_env):
    with pytest.raises(ValueError, match="no primitive shapes for robot 'xarm6'; arms that have them: panda"):
        make_env(robot="xarm6", sim={"collision_model": "primitive"})


def test_a_model_without_the_links_is_refused(tmp_path):
    urdf = tmp_path / "one.urdf"
    urdf.write_text('<robot name="one"><link name="base"/></robot>')
    with pytest.raises(ValueError, match="link 'panda_hand' not found"):
        collision_variant(str(urdf), "panda", "primitive")
