"""Cameras and visual randomization: spaces, determinism, what is recorded, and the held-out set."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from rlgrasp.envs import GraspEnv
from rlgrasp.envs.cameras import CameraSpec, object_cells
from rlgrasp.envs.randomization import Range
from rlgrasp.envs.visuals import GENERATORS, TRAIN_TEXTURES, VISUAL_PRESETS, repaint_patterns

WRIST_DEPTH = {"mount": "wrist", "modality": "depth"}


@pytest.fixture
def cam_env():
    envs = []

    def make(**kwargs):
        envs.append(GraspEnv(**kwargs))
        return envs[-1]

    yield make
    for env in envs:
        env.close()


@pytest.mark.parametrize(
    "modality, keys", [("depth", {"depth"}), ("rgb", {"rgb"}), ("rgbd", {"depth", "rgb"})]
)
def test_dict_observation_spaces_and_shapes(modality, keys, cam_env):
    env = cam_env(camera={"mount": "wrist", "modality": modality, "width": 48, "height": 40})
    assert set(env.observation_space.spaces) == {"state", "privileged"} | keys
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    if "depth" in keys:
        assert obs["depth"].shape == (1, 40, 48) and obs["depth"].dtype == np.float32
    if "rgb" in keys:
        assert obs["rgb"].shape == (3, 40, 48) and obs["rgb"].dtype == np.uint8
    # proprioception only: arm q, qd, finger width, grasp pos, vel, previous action
    assert obs["state"].shape == (7 + 7 + 1 + 3 + 3 + env.action_dim,)


@pytest.mark.parametrize("modality", ["depth", "rgbd"])
def test_stacked_frames_hold_the_last_images_oldest_first(modality, cam_env):
    single = cam_env(camera={"mount": "wrist", "modality": modality}, sim={"visual": "default"})
    stacked = cam_env(camera={"mount": "wrist", "modality": modality, "frames": 3}, sim={"visual": "default"})
    first, _ = stacked.reset(seed=4)
    one, _ = single.reset(seed=4)
    assert stacked.observation_space.contains(first)
    channels = {"depth": 1, "rgb": 3}
    for key, c in channels.items():
        if key in one:  # an episode starts with its first image repeated
            assert first[key].shape == (3 * c, 64, 64)
            np.testing.assert_array_equal(first[key], np.concatenate([one[key]] * 3))
    rng = np.random.default_rng(0)
    singles = [one]
    for _ in range(3):
        action = rng.uniform(-1, 1, single.action_dim)
        singles.append(single.step(action)[0])
        last = stacked.step(action)[0]
    for key in channels:
        if key in one:
            np.testing.assert_array_equal(last[key], np.concatenate([s[key] for s in singles[1:]]))
    again, _ = stacked.reset(seed=4)  # a new episode forgets the last one's images
    np.testing.assert_array_equal(again["depth"], first["depth"])


def test_camera_env_passes_gymnasiums_checker(cam_env):
    check_env(cam_env(camera=WRIST_DEPTH, sim={"visual": "default"}), skip_render_check=True)


def test_state_part_holds_nothing_about_the_object(cam_env):
    env = cam_env(camera=WRIST_DEPTH)
    obs, _ = env.reset(seed=1)
    names = ("arm_q", "arm_qd", "finger_width", "grasp_pos", "grasp_vel", "prev_action")
    expected = np.concatenate([obs["privileged"][env.obs_slices[n]] for n in names])
    assert np.array_equal(obs["state"], expected)


def test_cameras_and_visuals_leave_the_physics_of_a_seed_alone(cam_env):
    """The low-poly render model, the compact ground and the visual draws change no physics."""
    plain = cam_env(control={"mode": "joint_delta"})
    seen = cam_env(camera=WRIST_DEPTH, control={"mode": "joint_delta"}, sim={"visual": "default"})
    a, _ = plain.reset(seed=5)
    b, _ = seen.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(15):
        action = rng.uniform(-1, 1, plain.action_dim)
        a = plain.step(action)[0]
        b = seen.step(action)[0]
    assert np.array_equal(a, b["privileged"])


@pytest.mark.parametrize("visual", ["default", "repaint"])
def test_same_seed_same_images_and_visuals(cam_env, visual):
    runs = []
    for _ in range(2):
        env = cam_env(camera={"mount": "wrist", "modality": "rgbd"}, sim={"visual": visual})
        obs, info = env.reset(seed=3)
        obs2 = env.step(np.zeros(env.action_dim))[0]
        runs.append((obs, obs2, info["randomization"]))
    (o1, s1, r1), (o2, s2, r2) = runs
    for key in ("depth", "rgb"):
        assert np.array_equal(o1[key], o2[key]) and np.array_equal(s1[key], s2[key])
    assert r1 == r2


def test_visual_randomization_is_recorded_and_varies(cam_env):
    env = cam_env(camera={"mount": "wrist", "modality": "rgb"}, sim={"visual": "default"})
    draws = [env.reset(seed=s)[1]["randomization"] for s in range(4)]
    visual_keys = {k for k in draws[0] if k.startswith("visual_")}
    expected = {"visual_object_hue", "visual_light_elevation", "visual_depth_noise", "visual_fov_delta"}
    assert expected <= visual_keys
    assert len({d["visual_object_hue"] for d in draws}) == 4
    images = [env.reset(seed=s)[0]["rgb"] for s in range(2)]
    assert not np.array_equal(images[0], images[1])


def test_no_visual_randomization_adds_nothing_to_info(cam_env):
    info = cam_env(camera=WRIST_DEPTH, sim={"visual": "none"}).reset(seed=0)[1]
    assert not any(k.startswith("visual_") for k in info["randomization"])


@pytest.mark.parametrize("kind", sorted(GENERATORS))
def test_each_texture_generator_draws_a_pattern(kind):
    masks = [GENERATORS[kind](np.random.default_rng(seed), 64) for seed in range(3)]
    for mask in masks:
        assert mask.shape == (64, 64) and 0 <= mask.min() and mask.max() <= 1 and mask.std() > 0.05
    assert not np.array_equal(masks[0], masks[1])  # the generator's draws shape the pattern


def test_heldout_visuals_are_disjoint_from_training():
    held = VISUAL_PRESETS["heldout"]
    assert not set(held.textures) & set(TRAIN_TEXTURES)  # repaint patterns draw from these
    for name in ("default", "wide", "repaint", "repaint_scales"):
        train = VISUAL_PRESETS[name]
        assert set(train.textures) <= set(TRAIN_TEXTURES) and not set(held.textures) & set(train.textures)
        assert held.hues.low > train.hues.high
        assert held.light_elevation.high < train.light_elevation.low


def test_repaint_replaces_the_grounds_pixels_and_nothing_else(cam_env, monkeypatch):
    quiet = replace(VISUAL_PRESETS["default"], rgb_noise=Range(0.0, 0.0))  # no per-frame noise draws
    monkeypatch.setitem(VISUAL_PRESETS, "quiet", quiet)
    monkeypatch.setitem(VISUAL_PRESETS, "quiet_repaint", replace(quiet, ground_repaint=1.0))
    camera = {"mount": "wrist", "modality": "rgb"}
    plain, painted = (
        cam_env(camera=camera, sim={"visual": "quiet"}),
        cam_env(camera=camera, sim={"visual": "quiet_repaint"}),
    )
    seen, repainted = plain.reset(seed=2)[0]["rgb"], painted.reset(seed=2)[0]["rgb"]
    ground = painted.camera.render(painted.robot.camera_mount())["segmentation"] == painted.scene.ground
    assert 0.3 < ground.mean() < 1.0  # the wrist camera sees the ground, and more than the ground
    assert np.array_equal(seen[:, ~ground], repainted[:, ~ground])
    assert (seen[:, ground] != repainted[:, ground]).any(axis=0).mean() > 0.5
    action = np.zeros(painted.action_dim)
    first, second = painted.step(action)[0]["rgb"], painted.step(action)[0]["rgb"]
    assert not np.array_equal(first, second)  # a new pattern each frame


def test_object_cells_are_the_share_of_object_pixels_in_each_cell():
    mask = np.zeros((8, 12), bool)
    mask[0:2, 0:3] = True  # the whole first cell of a 4 x 4 grid (2 x 3 pixels a cell)
    mask[7, 11] = True  # one of the last cell's six pixels
    cells = object_cells(mask, 4)
    assert cells.shape == (16,) and cells.dtype == np.float32
    assert cells[0] == 1.0 and cells[15] == pytest.approx(1 / 6) and cells[1:15].sum() == 0


def test_a_camera_with_object_cells_reports_where_the_object_is_seen(cam_env):
    """The cells are a privileged part, last, after every part they leave where it was; they
    follow the object's pixels in the image (here the cube, lit by segmentation, against the
    same episode rendered with the object hidden), and no policy's state reads them."""
    camera = {"mount": "wrist", "modality": "rgb", "eye": [0.1, 0.0, -0.05]}
    plain, labelled = cam_env(camera=camera), cam_env(camera={**camera, "object_cells": 8})
    assert list(labelled.obs_slices)[:-1] == list(plain.obs_slices)
    assert labelled.obs_slices["object_cells"] == slice(plain.layout.size, plain.layout.size + 64)
    a, b = plain.reset(seed=0)[0], labelled.reset(seed=0)[0]
    assert np.array_equal(a["rgb"], b["rgb"]) and np.array_equal(a["state"], b["state"])
    np.testing.assert_array_equal(a["privileged"], b["privileged"][: plain.layout.size])
    cells = b["privileged"][labelled.obs_slices["object_cells"]].reshape(8, 8)
    segmentation = labelled.camera.render(labelled.robot.camera_mount())["segmentation"]
    seen = segmentation == labelled.scene.object
    assert seen.any() and np.array_equal(cells > 0, object_cells(seen, 8).reshape(8, 8) > 0)
    labelled.client.resetBasePositionAndOrientation(labelled.scene.object, [5.0, 5.0, -1.0], [0, 0, 0, 1])
    hidden = labelled.step(np.zeros(labelled.action_dim))[0]
    assert hidden["privileged"][labelled.obs_slices["object_cells"]].sum() == 0


def test_a_camera_with_a_ground_mask_reports_where_the_ground_is_seen(cam_env):
    """``ground_mask``: one uint8 channel a frame, 1 exactly where the segmentation shows the ground;
    the images and the state are those of the same camera without it (it is read, never drawn)."""
    camera = {"mount": "wrist", "modality": "rgb", "eye": [0.1, 0.0, -0.05], "frames": 2}
    plain, masked = cam_env(camera=camera), cam_env(camera={**camera, "ground_mask": True})
    assert masked.observation_space["ground_mask"].shape == (2, 64, 64)
    a, b = plain.reset(seed=0)[0], masked.reset(seed=0)[0]
    assert np.array_equal(a["rgb"], b["rgb"]) and np.array_equal(a["privileged"], b["privileged"])
    action = np.zeros(masked.action_dim, np.float32)
    action[2] = -1.0
    for _ in range(8):
        before, b = b, masked.step(action)[0]
    mask = b["ground_mask"]
    assert mask.dtype == np.uint8 and set(np.unique(mask)) == {0, 1}
    segmentation = masked.camera.render(masked.robot.camera_mount())["segmentation"]
    np.testing.assert_array_equal(mask[-1], segmentation == masked.scene.ground)
    np.testing.assert_array_equal(mask[0], before["ground_mask"][1])  # the older frame's, stacked
    check_env(masked.unwrapped, skip_render_check=True)


def test_repaint_patterns_fit_any_image_shape():
    patterns = repaint_patterns((48, 60), Range(0.0, 0.7), count=9)
    assert patterns.shape == (9, 3, 48, 60) and patterns.dtype == np.uint8
    assert all(p.std() > 5 for p in patterns)  # two colours each, not a flat fill


def test_magnified_repaint_patterns_have_larger_cells():
    """A pattern magnified s times is constant over s x s blocks, and is a corner of the pattern the
    same draw gives unmagnified: fewer, larger cells, the same generator and colours."""
    plain = repaint_patterns((64, 64), Range(0.0, 0.7), count=3)
    magnified = repaint_patterns((64, 64), Range(0.0, 0.7), count=3, scales=(1, 2, 4))
    np.testing.assert_array_equal(magnified[0], plain[0])
    for i, scale in ((1, 2), (2, 4)):
        blocks = magnified[i].reshape(3, 64 // scale, scale, 64 // scale, scale)
        assert (blocks == blocks[:, :, :1, :, :1]).all()
        corner = plain[i][:, : 64 // scale, : 64 // scale]
        np.testing.assert_array_equal(magnified[i][:, ::scale, ::scale], corner)


def test_depth_is_in_metres_and_sees_the_ground(cam_env):
    env = cam_env(camera=WRIST_DEPTH, randomization="none")
    depth = env.reset(seed=0)[0]["depth"]
    grasp_height = env.robot.grasp_point()[0][2]
    # the ground fills most of the image, about as far below the camera as the hand is high
    assert 0.02 <= float(np.median(depth)) <= 1.0
    assert float(np.median(depth)) > grasp_height


@pytest.mark.parametrize("mount", ["wrist", "fixed"])
def test_a_depth_cameras_computed_ground_matches_the_rendered_one(mount, cam_env):
    """A depth-only camera adds the ground plane itself instead of rendering it; an RGB-D camera
    (whose colour needs the ground drawn) sees the same depth on the same episode, wherever the arm
    moves. A ray through the wrong pixel point, a flipped row or a wrong axis would be centimetres off."""
    computed = cam_env(camera={"mount": mount, "modality": "depth"}, control={"mode": "joint_delta"})
    rendered = cam_env(camera={"mount": mount, "modality": "rgbd"}, control={"mode": "joint_delta"})
    assert computed.scene.ground is None and rendered.scene.ground is not None
    rng = np.random.default_rng(0)
    a, b = computed.reset(seed=3)[0], rendered.reset(seed=3)[0]
    for _ in range(15):
        assert np.abs(a["depth"] - b["depth"]).max() < 1e-4  # metres
        action = rng.uniform(-1, 1, computed.action_dim)
        a, b = computed.step(action)[0], rendered.step(action)[0]


@pytest.mark.parametrize(
    "camera, match",
    [
        ({"mount": "elbow"}, "camera.mount='elbow': valid mounts: wrist, fixed"),
        ({"modality": "thermal"}, "camera.modality='thermal'"),
        ({"width": 0}, "camera.width=0: must be an integer from 1 to 512"),
        ({"height": 513}, "camera.height=513"),
        ({"near": 0.5, "far": 0.5}, "need 0 < near < far"),
        ({"fov": 200}, "camera.fov=200"),
        ({"lens": 3}, "camera: unknown key 'lens'"),
        ({"frames": 0}, "camera.frames=0: must be an integer from 1 to 8"),
        ({"object_cells": 5}, "camera.object_cells=5: .* cells dividing the image.s width 64 and height 64"),
        ({"object_cells": -1}, "camera.object_cells=-1"),
        ({"ground_mask": True}, "camera.ground_mask=True: .* only with RGB .modality rgb or rgbd; here dep"),
    ],
)
def test_bad_camera_config_names_the_key(camera, match):
    with pytest.raises(ValueError, match=match.replace("(", r"\(").replace("[", r"\[")):
        CameraSpec.from_config(camera)


@pytest.mark.parametrize(
    "camera, link",
    [
        ({"mount": "fixed", "eye": [0.0, 0.0, 0.3]}, "panda_link1"),  # in the arm's shoulder
        ({"mount": "wrist", "eye": [0.0, 0.0, 0.0]}, "panda_link7"),  # in the wrist it hangs from
    ],
)
def test_a_camera_inside_the_robot_is_refused(cam_env, camera, link):
    with pytest.raises(ValueError, match=rf"camera.eye=.*inside the robot's link {link}"):
        cam_env(camera=camera)


def test_unknown_visual_preset_names_the_valid_ones(cam_env):
    with pytest.raises(ValueError, match="unknown visual preset 'bright'; valid presets: none, default"):
        cam_env(camera=WRIST_DEPTH, sim={"visual": "bright"})
