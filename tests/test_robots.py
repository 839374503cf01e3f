"""Every arm rlgrasp ships, and a user's arm from a YAML file: each builds, resets deterministically,
passes gymnasium's checker, drives its three control modes, takes the robot's randomization, gives
camera observations and is grasped with by the scripted expert; bad descriptions fail in one line;
a checkpoint of one arm is refused by an env of another."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pybullet
import pybullet_data
import pytest
from gymnasium.utils.env_checker import check_env
from omegaconf import OmegaConf

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert, grasp_env
from rlgrasp.envs.experts import lift as expert_module
from rlgrasp.envs.render_model import mesh_bounds
from rlgrasp.envs.robot import ROBOTS, robot_label
from rlgrasp.envs.robot_spec import BUILTIN_DIR, BUILTIN_ROBOTS, builtin_spec, spec_from_file
from rlgrasp.evaluation.source import EvaluationError, check_robot
from rlgrasp.overrides import rewrite

PANDA, KUKA_IIWA, XARM6 = (builtin_spec(name) for name in ("panda", "kuka_iiwa", "xarm6"))
ARMS = {"panda": (PANDA, 7), "kuka_iiwa": (KUKA_IIWA, 7), "xarm6": (XARM6, 6)}
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def arm_env():
    """``arm_env(robot, **kwargs)``: a grasp env of that arm, closed at the end of the test."""
    envs = []

    def make(robot, **kwargs):
        env = PandaGraspEnv(robot=robot, **kwargs)
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()


def test_the_shipped_arms_are_registered_from_their_files():
    assert BUILTIN_ROBOTS == tuple(ARMS) and all(ROBOTS[n] is builtin_spec(n) for n in ARMS)
    assert {n: ROBOTS[n].label for n in ARMS} == {n: n for n in ARMS}
    assert sorted(p.stem for p in BUILTIN_DIR.glob("*.yaml")) == sorted(ARMS)


def test_a_non_editable_install_ships_the_arms_files():
    tomllib = pytest.importorskip("tomllib")  # python >= 3.11
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    shipped = {p for glob in data["rlgrasp.envs"] for p in (ROOT / "rlgrasp" / "envs").glob(glob)}
    assert set(BUILTIN_DIR.glob("*.yaml")) <= shipped


@pytest.mark.parametrize("robot", ARMS)
def test_each_arm_builds_sized_from_its_joints_and_passes_the_checker(robot, arm_env):
    env = arm_env(robot)
    dof = ARMS[robot][1]
    assert env.robot.arm_dof == dof
    assert env.obs_slices["arm_q"].stop - env.obs_slices["arm_q"].start == dof
    obs, _ = env.reset(seed=0)
    assert np.allclose(obs[env.obs_slices["arm_q"]], ARMS[robot][0].neutral_pose, atol=0.1)  # default noise
    assert obs[env.obs_slices["finger_width"]][0] == pytest.approx(ARMS[robot][0].max_finger_width, abs=0.01)
    check_env(env, skip_render_check=True)


@pytest.mark.parametrize("robot", ARMS)
def test_each_arm_resets_and_steps_deterministically(robot, arm_env):
    a, b = arm_env(robot, randomization="wide"), arm_env(robot, randomization="wide")
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (10, a.action_dim)).astype(np.float32)
    for env in (a, b):
        env.reset(seed=3)
    np.testing.assert_array_equal(a.reset(seed=7)[0], b.reset(seed=7)[0])
    for action in actions:
        np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])


@pytest.mark.parametrize("robot", ARMS)
def test_the_grasp_point_follows_ee_delta_and_ik_reaches_down(robot, arm_env):
    env = arm_env(robot, randomization="none")
    env.reset(seed=0)
    start = env.robot.grasp_point()[0]
    for _ in range(3):
        env.step(np.array([0.0, 0.0, -1.0, 1.0], np.float32))
    moved = env.robot.grasp_point()[0] - start
    assert moved[2] < -0.08 and np.abs(moved[:2]).max() < 0.02
    target = np.array([0.65, 0.08, 0.02])  # a corner of the object's region, at grasp height
    for _ in range(5):
        env.robot.reset(env.robot.inverse_kinematics(target))
    assert np.linalg.norm(env.robot.grasp_point()[0] - target) < 0.01


@pytest.mark.parametrize("robot", ARMS)
def test_joint_modes_move_the_arm_and_gravity_compensation_holds_it(robot, arm_env):
    dof = ARMS[robot][1]
    for mode in ("joint_delta", "joint_torque"):
        env = arm_env(robot, randomization="none", control={"mode": mode})
        assert env.action_space.shape == (dof + 1,)
        env.reset(seed=0)
        q0 = env.robot.joint_state()[0]
        idle = np.zeros(dof + 1, np.float32)
        idle[-1] = 1.0
        for _ in range(10):
            env.step(idle)
        assert np.abs(env.robot.joint_state()[0] - q0).max() < 0.01, mode
        push = idle.copy()
        push[0] = 1.0
        for _ in range(3):
            env.step(push)
        assert env.robot.joint_state()[0][0] - q0[0] > 0.05, mode


@pytest.mark.parametrize("robot", ARMS)
def test_the_robot_randomization_reaches_each_arm(robot, arm_env):
    env = arm_env(robot, randomization="wide")
    _, info = env.reset(seed=1)
    ep, r, c = info["randomization"], env.robot, env.client
    assert r.finger_force == pytest.approx(ep["finger_force"])
    assert r.position_gain == pytest.approx(ARMS[robot][0].position_gain * ep["position_gain_scale"])
    friction = ep["finger_friction"] * ARMS[robot][0].finger_friction_scale
    assert c.getDynamicsInfo(r.body, r.finger_links[1])[1] == pytest.approx(friction)
    q = r.joint_state()[0]
    assert 0 < np.abs(q - np.asarray(r.neutral_pose)).max() < 0.5  # start-pose noise, within reason


def test_an_arms_pad_friction_scales_the_episodes_finger_friction(arm_env):
    env = arm_env({**PANDA.as_mapping(), "finger_friction_scale": 1.5}, randomization="default")
    _, info = env.reset(seed=0)
    for link in env.robot.finger_links:
        friction = env.client.getDynamicsInfo(env.robot.body, link)[1]
        assert friction == pytest.approx(1.5 * info["randomization"]["finger_friction"])


@pytest.mark.parametrize("robot", ARMS)
def test_a_wrist_camera_rides_on_each_arm(robot, arm_env):
    env = arm_env(
        robot,
        randomization="none",
        objects="primitives",
        camera={"mount": "wrist", "modality": "depth", "width": 32, "height": 32},
    )
    obs, _ = env.reset(seed=0)
    depth = obs["depth"]
    assert depth.shape == (1, 32, 32) and np.isfinite(depth).all()
    # It looks down along the fingers: the ground and the object are in view, nearer than `far`.
    assert np.median(depth) < 0.5 and depth.max() - depth.min() > 0.02


@pytest.mark.parametrize("robot", ["kuka_iiwa", "xarm6"])
def test_cameras_see_the_arms_links_as_boxes_and_the_physics_is_unchanged(robot, arm_env):
    """The render model (``low_poly_meshes: boxes``) boxes every link but the gripper's and leaves
    every collision shape as it is: the arm moves as the arm without a camera does."""
    plain = arm_env(robot, control={"mode": "joint_delta"})
    seen = arm_env(
        robot,
        camera={"mount": "fixed", "modality": "depth", "width": 32, "height": 32},
        control={"mode": "joint_delta"},
    )
    shapes = {s[1]: s[2] for s in seen.client.getVisualShapeData(seen.robot.body)}
    keep = {j for j, name in seen.robot.link_names.items() if name in seen.robot.wrist_names}
    assert shapes and all(shape == pybullet.GEOM_BOX for link, shape in shapes.items() if link not in keep)
    assert any(shapes.get(link) == pybullet.GEOM_MESH for link in keep)  # the gripper keeps its meshes
    a, b = plain.reset(seed=5)[0], seen.reset(seed=5)[0]
    rng = np.random.default_rng(0)
    for _ in range(10):
        action = rng.uniform(-1, 1, plain.action_dim)
        a, b = plain.step(action)[0], seen.step(action)[0]
    np.testing.assert_array_equal(a, b["privileged"])


def test_mesh_bounds_read_binary_stl_with_a_solid_header_and_obj():
    root = pybullet_data.getDataPath()
    # A binary STL whose 80-byte header starts with "solid", as an ASCII one does.
    low, high = mesh_bounds(f"{root}/xarm/xarm_gripper/meshes/base_link.STL")
    assert np.all(high - low > 0.03) and np.all(high - low < 0.2)
    low, high = mesh_bounds(f"{root}/cube.obj")
    np.testing.assert_allclose([low, high], [[-0.5] * 3, [0.5] * 3])
    assert mesh_bounds(f"{root}/racecar/meshes/cone.dae") is None  # not read: kept as a mesh


@pytest.mark.parametrize("robot", ARMS)
def test_each_arms_expert_lifts_the_cube(robot, arm_env):
    env = arm_env(robot)
    expert = ScriptedExpert.for_env(env)
    successes = 0
    for seed in range(10):
        obs, info = env.reset(seed=seed)
        expert.reset()
        for _ in range(env.sim.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
        successes += bool(info["is_success"])
    assert successes >= 7


# --- a user's arm: a YAML file and a model file, no code ---------------------------------------
def _yaml_arm(tmp_path, spec, **changes):
    """The arm's description written to a YAML file as a user would, read back as the config would."""
    data = {**spec.as_mapping(), **changes}
    data["model"] = f"{pybullet_data.getDataPath()}/{spec.model}"
    path = tmp_path / "my_arm.yaml"
    path.write_text(OmegaConf.to_yaml(OmegaConf.create({"robot": data})))
    return OmegaConf.load(path).robot


def test_an_arm_from_yaml_is_the_shipped_arm(tmp_path, arm_env):
    robot = _yaml_arm(tmp_path, XARM6, name="")
    env, shipped = arm_env(robot, randomization="wide"), arm_env("xarm6", randomization="wide")
    np.testing.assert_array_equal(env.reset(seed=5)[0], shipped.reset(seed=5)[0])
    action = np.array([0.3, -0.2, -1.0, 1.0], np.float32)
    np.testing.assert_array_equal(env.step(action)[0], shipped.step(action)[0])
    assert robot_label(robot) == "xarm6_with_gripper"  # no name: the model file's stem


def test_a_shipped_arms_file_copied_as_a_users_config_is_that_arm(tmp_path):
    """The walk-through's claim: a built-in arm's file, copied to configs/robot/my_arm.yaml with an
    absolute model path, is the same arm."""
    text = (BUILTIN_DIR / "kuka_iiwa.yaml").read_text()
    model = f"{pybullet_data.getDataPath()}/{KUKA_IIWA.model}"
    mine = tmp_path / "my_arm.yaml"
    mine.write_text(text.replace(f"model: {KUKA_IIWA.model}", f"model: {model}"))
    assert spec_from_file(mine) == dataclasses.replace(KUKA_IIWA, model=model)
    assert OmegaConf.load(mine).robot.name == "kuka_iiwa" and text.startswith("# @package env\n")


def test_a_user_arm_on_the_command_line_reaches_env_robot(train_cfg):
    arm = "{model:franka_panda/panda.urdf,name:mine}"
    assert rewrite([f"robot={arm}"]) == ["robot=panda", f"env.robot={arm}"]
    cfg = train_cfg(*rewrite(["robot=kuka_iiwa"]))
    assert cfg.env.robot == "kuka_iiwa"
    cfg = train_cfg(*rewrite([f"robot={arm}"]))
    assert dict(cfg.env.robot) == {"model": "franka_panda/panda.urdf", "name": "mine"}


PANDA_FINGERS = [{"joint": f"panda_finger_joint{i}", "open": 0.04} for i in (1, 2)]
BAD_ARMS = [
    (
        "missing model file",
        {"model": "/tmp/nowhere/arm.urdf"},
        FileNotFoundError,
        "robot.model: model file not found: /tmp/nowhere/arm.urdf",
    ),
    (
        "not a model file",
        {"model": "franka_panda/meshes/collision/hand.obj"},
        ValueError,
        "hand.obj': must be a .urdf or .sdf file",
    ),
    (
        "joint not in the model",
        {"arm_joints": [*PANDA.arm_joints[:6], "panda_joint9"]},
        ValueError,
        "robot.arm_joints: 'panda_joint9' is not a movable joint of .*panda.urdf; its movable joints: "
        "panda_joint1",
    ),
    (
        "grasp link not in the model",
        {"grasp_link": "panda_tcp"},
        ValueError,
        "robot.grasp_link: 'panda_tcp' is not a link of .*; its links: panda_link1",
    ),
    (
        "finger joint not in the model",
        {"fingers": [{"joint": "panda_finger", "open": 0.04}]},
        ValueError,
        "robot.fingers: 'panda_finger' is not a movable joint",
    ),
    (
        "fingers that do not open",
        {"fingers": [{**f, "open": 0.0, "closed": 0.04} for f in PANDA_FINGERS]},
        ValueError,
        "robot.fingers: the finger links panda_leftfinger, panda_rightfinger are 0.080 m apart "
        "closed and 0.000 m open",
    ),
    (
        "finger position outside its limits",
        {"fingers": [{**f, "open": 0.4} for f in PANDA_FINGERS]},
        ValueError,
        r"robot.fingers: panda_finger_joint1 open=0.4 is outside its limits \[0.0, 0.04\]",
    ),
    (
        "neutral pose outside the limits",
        {"neutral_pose": [0.0, 0.41, 0.0, 1.85, 0.0, 2.26, 0.79]},
        ValueError,
        r"robot.neutral_pose: panda_joint4=1.85 is outside its limits \[-3.1416, 0.0\]",
    ),
    (
        "neutral pose of another size",
        {"neutral_pose": [0.0, 0.41]},
        ValueError,
        "robot.neutral_pose has 2 angles: must have one per arm joint",
    ),
    (
        "unknown render rule",
        {"low_poly_meshes": "spheres"},
        ValueError,
        "robot.low_poly_meshes='spheres': must be null, boxes or",
    ),
    (
        "unknown key",
        {"grasp_lnk": "x"},
        ValueError,
        "robot.grasp_lnk: unknown key; a robot has model, arm_joints",
    ),
    (
        "a finger entry that is not one",
        {"fingers": ["panda_finger_joint1"]},
        ValueError,
        r"robot.fingers\[0\]='panda_finger_joint1': must be \{joint: <name>, open: <position>",
    ),
    (
        "a mimic joint following no motor",
        {
            "fingers": [
                {**PANDA_FINGERS[0], "mimic": "panda_finger_joint2"},
                {**PANDA_FINGERS[1], "mimic": "panda_finger_joint1"},
            ]
        },
        ValueError,
        "robot.fingers: panda_finger_joint1 mimics 'panda_finger_joint2', which must be a finger "
        "joint with a motor of its own",
    ),
    (
        "a pad friction that is not positive",
        {"finger_friction_scale": 0},
        ValueError,
        "robot.finger_friction_scale=0: must be a number > 0",
    ),
    (
        "an unknown expert setting",
        {"expert": {"reach": 0.05}},
        ValueError,
        "robot.expert.reach: unknown key; the expert's settings: finger_reach, floor_clearance, hover",
    ),
    (
        "an expert setting out of range",
        {"expert": {"finger_reach": -0.01}},
        ValueError,
        r"robot.expert.finger_reach=-0.01: must be a number of metres in \[0.0, 0.2\]",
    ),
    (
        "an expert setting that is not a number",
        {"expert": {"floor_clearance": "low"}},
        ValueError,
        r"robot.expert.floor_clearance='low': must be a number of metres",
    ),
    (
        "expert settings that are not a mapping",
        {"expert": [0.05]},
        ValueError,
        "robot.expert=\\[0.05\\]: must be a mapping of finger_reach, floor_clearance, hover",
    ),
]


@pytest.mark.parametrize("what, changes, error, match", BAD_ARMS, ids=[c[0] for c in BAD_ARMS])
def test_a_bad_arm_fails_in_one_line_naming_the_key(what, changes, error, match):
    mapping = {**PANDA.as_mapping(), **changes}
    with pytest.raises(error, match=match) as info:
        PandaGraspEnv(robot=mapping)
    assert "\n" not in str(info.value)


def test_an_arms_expert_settings_reach_its_expert(tmp_path, arm_env):
    """The description's ``expert`` key sets where the expert grasps; an arm without one (the Panda)
    keeps the defaults, and a user's YAML file sets it as a shipped arm's does."""
    panda = ScriptedExpert.for_env(arm_env("panda"))
    assert (panda.finger_reach, panda.floor_clearance, panda.hover) == (
        expert_module.FINGER_REACH,
        expert_module.FLOOR_CLEARANCE,
        0.06,
    )
    xarm = ScriptedExpert.for_env(arm_env("xarm6"))
    assert (xarm.finger_reach, xarm.floor_clearance) == (
        XARM6.expert["finger_reach"],
        XARM6.expert["floor_clearance"],
    )
    mine = arm_env(_yaml_arm(tmp_path, PANDA, expert={"finger_reach": 0.05, "hover": 0.08}))
    expert = ScriptedExpert.for_env(mine, hover=0.1)  # an explicit setting wins over the arm's
    assert (expert.finger_reach, expert.floor_clearance, expert.hover) == (
        0.05,
        expert_module.FLOOR_CLEARANCE,
        0.1,
    )
    # the grasp height follows: a 10 cm tall upright box resting on the floor (centre at 5 cm)
    upright, extents = np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.04, 0.06, 0.10])
    assert expert_module.grasp_plan(upright, extents, 0.05)[1] == pytest.approx(0.1 - 0.035)
    assert expert_module.grasp_plan(upright, extents, 0.05, 0.055, 0.006)[1] == pytest.approx(0.1 - 0.055)
    assert expert_module.grasp_plan(upright, extents, 0.05, 0.2, 0.006)[1] == pytest.approx(0.006)


def test_the_expert_keeps_its_yaw_when_two_widths_tie():
    """A cube's two sides differ by the observation's noise: the hand must not turn back and forth
    between them (the iiwa's 'never grasped' cubes hovered so until the episode ended)."""
    turned = np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)])  # the box turned 0.6 rad about z
    plan = expert_module.grasp_plan
    for width_x in (0.0580, 0.0585, 0.0590):  # x the narrower, equal, the wider, all within the tie
        extents = np.array([width_x, 0.0585, 0.05])
        near_zero = plan(turned, extents, 0.025)[0]
        assert plan(turned, extents, 0.025, current_yaw=near_zero)[0] == pytest.approx(near_zero)
        other = expert_module._wrap_half_turn(near_zero + math.pi / 2)
        assert plan(turned, extents, 0.025, current_yaw=other)[0] == pytest.approx(other)
    # beyond the tie the narrower side wins whatever the hand's yaw
    wide_y = np.array([0.04, 0.06, 0.05])
    assert plan(turned, wide_y, 0.025, current_yaw=0.0)[2] == pytest.approx(0.04)
    assert plan(turned, wide_y, 0.025, current_yaw=-1.0)[2] == pytest.approx(0.04)


def test_a_missing_key_is_named():
    mapping = PANDA.as_mapping()
    del mapping["grasp_link"]
    with pytest.raises(ValueError, match="robot.grasp_link: missing; a robot needs model, arm_joints"):
        PandaGraspEnv(robot=mapping)


def test_unknown_robot_names_the_valid_ones():
    with pytest.raises(ValueError, match="unknown robot 'ur5'; valid robots: panda, kuka_iiwa, xarm6"):
        PandaGraspEnv(robot="ur5")


def test_torque_control_is_refused_where_the_model_says_it_is_not_meaningful(monkeypatch):
    scenes = []

    class RecordedScene(grasp_env.Scene):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            scenes.append(self)

    monkeypatch.setattr(grasp_env, "Scene", RecordedScene)
    mapping = {**dataclasses.asdict(PANDA), "torque_control": False, "fingers": PANDA_FINGERS}
    with pytest.raises(ValueError, match="control.mode=joint_torque: this arm's model has no meaningful"):
        PandaGraspEnv(robot=mapping, control={"mode": "joint_torque"})
    # The refused env leaves no physics server behind for the garbage collector.
    assert len(scenes) == 1 and not pybullet.isConnected(scenes[0].client._client)


# --- a policy never leaks across arms ---------------------------------------------------------
def test_a_checkpoint_of_one_arm_is_refused_by_an_env_of_another():
    with pytest.raises(
        EvaluationError, match="was trained on the robot 'kuka_iiwa' and the env has the robot 'panda'"
    ):
        check_robot({"robot": "kuka_iiwa"}, {"robot": "panda"}, "checkpoint x.pt")
    with pytest.raises(EvaluationError, match="trained on the robot 'panda' .* the robot 'mine'"):
        check_robot({}, {"robot": {"name": "mine", "model": "arm.urdf"}}, "checkpoint x.pt")  # old: the Panda
    check_robot({"robot": "xarm6"}, {"robot": "xarm6"}, "checkpoint x.pt")
