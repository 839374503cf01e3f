"""Object sets: every set builds, places its objects at rest, replays bit for bit, and is graspable."""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pybullet_data
import pytest
from gymnasium.utils.env_checker import check_env
from omegaconf import OmegaConf

from rlgrasp.compose import compose_eval, compose_train
from rlgrasp.envs import PandaGraspEnv, ScriptedExpert
from rlgrasp.envs.objects import (
    BROKEN_RANDOM_URDFS,
    SET_NAMES,
    ObjectSampler,
    random_urdf_choice,
    random_urdf_numbers,
)
from rlgrasp.overrides import rewrite
from tests.helpers import run_entry

SETS = list(SET_NAMES) + [["primitives", "random_urdfs_train"]]


def _box_obj(path, size) -> str:
    """An OBJ box of the given size (m), its corner at the origin (so not centred)."""
    x, y, z = size
    corners = [(i * x, j * y, k * z) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    lines = [f"v {a} {b} {c}" for a, b, c in corners] + [f"f {' '.join(map(str, f))}" for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


@pytest.mark.parametrize("objects", SETS, ids=str)
def test_each_set_builds_and_rests_where_it_is_placed(objects, make_env):
    env = make_env(objects=objects, randomization="default")
    group_names = [objects] if isinstance(objects, str) else objects
    prefixes = {g.removesuffix("_train").removesuffix("_test") for g in group_names}
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        name = info["object"]
        assert isinstance(name, str)
        assert name.split("/")[0] in prefixes
        extents = obs[env.obs_slices["object_extents"]]
        np.testing.assert_allclose(extents, info["object_extents"], atol=0.01)  # sensing noise
        assert 0.005 < min(extents[:2]) < 0.075 and np.all(extents > 0.003)
        for _ in range(5):  # fingers open, arm far above: the object must not fall or sink
            obs, _, _, _, info = env.step(np.array([0, 0, 0, 1], np.float32))
        assert abs(float(info["lift_height"])) < 0.006, name


@pytest.mark.parametrize("objects", ["primitives", "random_urdfs_test", "toys"])
def test_gymnasium_check_env_passes_for_every_set(objects, make_env):
    env = make_env(objects=objects)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env)


def _trace(env, seed, actions):
    obs, info = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, reward, *_ = env.step(a)
        out.append(np.append(obs, reward))
    return info["object"], out


@pytest.mark.parametrize("objects", [["primitives", "random_urdfs_train", "toys"]], ids=["mixture"])
def test_same_seed_same_object_and_episode_bit_for_bit(objects, make_env):
    env_a, env_b = make_env(objects=objects), make_env(objects=objects)
    actions = np.random.default_rng(0).uniform(-1, 1, (15, 4)).astype(np.float32)
    names = set()
    for seed in range(4):
        name_a, trace_a = _trace(env_a, seed, actions)
        _trace(env_a, seed + 100, actions)  # another object in between must leave no trace
        name_b, trace_b = _trace(env_b, seed, actions)
        name_c, trace_c = _trace(env_a, seed, actions)
        assert name_a == name_b == name_c
        for x, y, z in zip(trace_a, trace_b, trace_c):
            np.testing.assert_array_equal(x, y)
            np.testing.assert_array_equal(x, z)
        names.add(name_a)
    assert len(names) > 1  # the seeds really drew different objects


def test_random_urdfs_split_is_fixed_disjoint_and_complete():
    train, test = random_urdf_numbers("train"), random_urdf_numbers("test")
    assert len(train) == 900 and len(test) == 100
    assert set(train).isdisjoint(test) and set(train) | set(test) == set(range(1000))
    assert test[:3] == [0, 10, 20] and all(n % 10 == 0 for n in test)
    rng = np.random.default_rng(0)
    drawn = {ObjectSampler("random_urdfs_test").draw(rng).name for _ in range(50)}
    assert all(name.startswith("random_urdfs/") and name.endswith("0") for name in drawn)


def test_every_drawable_random_urdf_mesh_parses():
    for n in random_urdf_numbers("all"):
        if n in BROKEN_RANDOM_URDFS:
            with pytest.raises(ValueError, match=f"{n}.obj"):
                random_urdf_choice(n, max_width=0.05)
        else:
            random_urdf_choice(n, max_width=0.05)
    train = ObjectSampler("random_urdfs_train").spec.groups[0]
    assert len(train) == 899 and 168 not in train


def test_fitted_meshes_fit_the_hand():
    sampler = ObjectSampler("random_urdfs_test")
    widths = []
    for n in random_urdf_numbers("test")[:30]:
        choice = random_urdf_choice(n, max_width=0.05)
        assert choice.name == f"random_urdfs/{n:03d}"
        widths.append(min(sampler.geometry(choice).extents[:2]))
    assert max(widths) <= 0.05 + 1e-6
    assert min(widths) < 0.049  # small objects are left at their own size, not blown up


@pytest.mark.parametrize("objects", ["cube", "primitives", "random_urdfs_test", "toys"])
def test_expert_lifts_a_small_sample_of_each_set(objects, make_env):
    env = make_env(objects=objects, randomization="default", control={"ee_yaw": True})
    expert = ScriptedExpert(env.obs_slices, action_dim=env.action_dim)
    successes = 0
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        expert.reset()
        for _ in range(env.sim.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
        successes += bool(info["is_success"])
    assert successes >= 3


def test_user_folder_of_obj_files(tmp_path, make_env):
    _box_obj(tmp_path / "small.obj", (0.03, 0.04, 0.06))
    _box_obj(tmp_path / "wide.obj", (0.12, 0.10, 0.05))  # wider than the hand: fitted to 5 cm
    (tmp_path / "notes.txt").write_text("not a model")
    env = make_env(objects={"paths": [str(tmp_path)]}, randomization="none")
    seen = {}
    for seed in range(8):
        obs, info = env.reset(seed=seed)
        seen[info["object"]] = info["object_extents"]
        for _ in range(3):
            obs, _, _, _, info = env.step(np.array([0, 0, 0, 1], np.float32))
        assert abs(float(info["lift_height"])) < 0.004  # rests on its own (off-centre) bottom
    assert set(seen) == {"paths/small.obj", "paths/wide.obj"}
    np.testing.assert_allclose(seen["paths/small.obj"], [0.03, 0.04, 0.06], atol=1e-6)
    np.testing.assert_allclose(seen["paths/wide.obj"], [0.06, 0.05, 0.025], atol=1e-6)
    glob_env = make_env(objects={"paths": [str(tmp_path / "s*.obj")]})
    assert glob_env.reset(seed=0)[1]["object"] == "paths/small.obj"


def test_without_a_range_an_object_keeps_its_own_mass_and_friction(make_env):
    mug = os.path.join(pybullet_data.getDataPath(), "objects/mug.urdf")
    env = make_env(objects={"paths": [mug]}, randomization="none")
    _, info = env.reset(seed=0)
    assert info["randomization"]["object_mass"] == pytest.approx(1.0)  # mug.urdf says 1 kg
    assert env.client.getDynamicsInfo(env.scene.object, -1)[0] == pytest.approx(1.0)
    env = make_env(objects={"paths": [mug]}, randomization={"object_mass": 0.2})
    _, info = env.reset(seed=0)
    assert env.client.getDynamicsInfo(env.scene.object, -1)[0] == pytest.approx(0.2)


# --- bad input, all at construction ------------------------------------------------------------


def test_unknown_set_names_the_valid_ones():
    with pytest.raises(ValueError, match="'kitchen'.*cube, primitives, random_urdfs"):
        PandaGraspEnv(objects="kitchen")
    with pytest.raises(ValueError, match="'kitchen'.*toys"):
        PandaGraspEnv(objects=["primitives", "kitchen"])
    with pytest.raises(ValueError, match="unknown objects key.*'colour'"):
        PandaGraspEnv(objects={"sets": ["cube"], "colour": "red"})


def test_empty_glob_and_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nothing\*\.obj.*matches no"):
        PandaGraspEnv(objects={"paths": [str(tmp_path / "nothing*.obj")]})
    with pytest.raises(FileNotFoundError, match="missing.obj"):
        PandaGraspEnv(objects={"paths": [str(tmp_path / "missing.obj")]})


def test_unparsable_meshes_name_the_file(tmp_path):
    (tmp_path / "broken.obj").write_text("v 0.1 zero 0.3\n")
    with pytest.raises(ValueError, match="broken.obj"):
        PandaGraspEnv(objects={"paths": [str(tmp_path / "broken.obj")]})
    (tmp_path / "empty.obj").write_text("# no vertices\n")
    with pytest.raises(ValueError, match="empty.obj.*no usable vertices"):
        PandaGraspEnv(objects={"paths": [str(tmp_path / "empty.obj")]})
    (tmp_path / "bad.urdf").write_text("<robot><link name='a'>")
    with pytest.raises(ValueError, match="bad.urdf"):
        PandaGraspEnv(objects={"paths": [str(tmp_path / "bad.urdf")]})


def test_object_too_large_for_the_hand(tmp_path):
    path = _box_obj(tmp_path / "crate.obj", (0.2, 0.2, 0.1))
    with pytest.raises(ValueError, match="crate.obj is too large for the hand"):
        PandaGraspEnv(objects={"paths": [path], "scale": 1.0})
    with pytest.raises(ValueError, match="max_width"):
        PandaGraspEnv(objects={"paths": [path], "max_width": 0.075})


# --- one spelling on every command line: objects=<set> or objects={paths:[...]} ----------------


def test_objects_spelling_reaches_env_objects_in_training_and_evaluation(tmp_path):
    """A dict or list for the `objects` group's name is the env's `objects` value, in training
    (env.objects exists) as in evaluation (env holds only the keywords given: ++ adds them)."""
    own = "objects={paths:[/my/meshes]}"
    assert rewrite([own, "env.objects=toys"]) == [
        "objects=cube",
        "env.objects={paths:[/my/meshes]}",
        "env.objects=toys",
    ]
    assert rewrite([own, "env.sim.max_episode_steps=80", "randomization={preset:wide}"], open_env=True) == [
        "++env.objects={paths:[/my/meshes]}",
        "++env.sim.max_episode_steps=80",
        "randomization={preset:wide}",
    ]
    out = f"paths.output_dir={tmp_path}"
    mixed = compose_train([*rewrite(["objects=[primitives,toys]", "randomization={object_mass:0.2}"]), out])
    assert OmegaConf.to_container(mixed.env.objects) == ["primitives", "toys"]
    assert OmegaConf.to_container(mixed.env.randomization) == {"object_mass": 0.2}
    # The value replaces an experiment's objects, here a list (Hydra alone refuses a dict over it).
    own_only = compose_train(["experiment=grasp_objects_ppo", *rewrite([own]), out])
    assert OmegaConf.to_container(own_only.env.objects) == {"paths": ["/my/meshes"]}
    assert compose_train(["objects=primitives", out]).env.objects == "primitives"  # a set: the group
    for spelling in (own, "env.objects={paths:[/my/meshes]}"):
        ev = compose_eval(rewrite([spelling], open_env=True))
        assert OmegaConf.to_container(ev.env) == {"objects": {"paths": ["/my/meshes"]}}
    assert compose_eval(["objects=random_urdfs_test"]).env.objects == "random_urdfs_test"


def test_evaluating_own_meshes_names_them(tmp_path):
    """rlgrasp-eval with objects={paths:[folder]}, as typed: the episodes use those meshes and the
    summary says which objects (and that the scripted baseline has no training objects)."""
    _box_obj(tmp_path / "small.obj", (0.03, 0.04, 0.06))
    code = run_entry(
        "eval",
        [
            "policy=scripted",
            f"objects={{paths:[{tmp_path}]}}",
            "episodes=2",
            "video=false",
            "plots=false",
            f"outputs_root={tmp_path}",
            "name=own",
        ],
        tmp_path,
    )
    assert code == 0
    out = tmp_path / "eval" / "scripted" / "own"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["config"]["env"]["objects"] == {"paths": [str(tmp_path)]}
    assert metrics["objects_label"] == f"{{paths: [{tmp_path}]}}"
    assert {r["object"] for r in metrics["success_by_object"]} == {"paths/small.obj"}
    assert f"| objects                          | {{paths: [{tmp_path}]}}" in (out / "summary.md").read_text()
