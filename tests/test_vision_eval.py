"""Camera policies in evaluation, export and enjoy: a camera checkpoint as ``Distiller.save`` writes
it (random weights, no training run), its teacher on the same episodes, held-out visuals, the camera's
view in the videos, the exported file's inputs, the GUI's camera preview."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.compose import compose_config, compose_eval
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.envs.scene import VIEWER_TARGET, ViewerConfig
from rlgrasp.evaluation import EvaluationError
from rlgrasp.evaluation.cli import evaluate
from rlgrasp.evaluation.enjoy import camera_line, gui_settings, play, register_enjoy_config, set_up_gui
from rlgrasp.evaluation.episodes import run_episodes
from rlgrasp.evaluation.source import prepare
from rlgrasp.evaluation.teacher import prepare_teacher
from rlgrasp.evaluation.views import beside, camera_view, depth_image, upscale
from rlgrasp.export import ExportError, export, load_exported, record, register_export_config
from rlgrasp.policy_file import policy_from_checkpoint
from tests.helpers import STUDENT_MODEL, TEACHER, make_run, make_student

ROOT = Path(__file__).resolve().parents[1]
MODEL = STUDENT_MODEL
KEYPOINTS = {**MODEL, "strides": [2, 2, 1], "pooling": "keypoints"}  # kernel sizes: the default 8, 4, 3


@pytest.fixture(scope="module")
def student(tmp_path_factory) -> Path:
    return make_student(tmp_path_factory.mktemp("student"))


def _cfg(*overrides: str):
    return compose_eval(list(overrides))


QUIET = ("video=false", "plots=false", "tensorboard=false")


# --- the checkpoint's policy ---------------------------------------------------------------------
def test_policy_from_checkpoint_rebuilds_the_camera_policy(student: Path) -> None:
    ckpt = torch.load(student, weights_only=True)
    policy = policy_from_checkpoint(ckpt)
    assert set(policy.in_keys) >= {"observation", "depth"}
    env = env_factory(ckpt["config"]["env"])()
    try:
        obs, _ = env.reset(seed=0)
    finally:
        env.close()
    td = TensorDict(
        {"observation": torch.as_tensor(obs["state"])[None], "depth": torch.as_tensor(obs["depth"])[None]},
        [1],
    )
    td2 = td.clone()
    td2["depth"] = torch.full_like(td["depth"], 0.5)
    with torch.no_grad():
        action = policy(td)["action"]
        other = policy(td2)["action"]
    assert action.shape == (1, 8) and float(action.abs().max()) <= 1.0
    # The weights are the checkpoint's: another image gives another action.
    assert not torch.equal(other, action)


# --- evaluation ----------------------------------------------------------------------------------
@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_camera_policy_beside_its_teacher_on_held_out_visuals(student: Path, tmp_path: Path) -> None:
    """The student and its teacher on the same seeds, under visuals the student never saw: both
    successes with Wilson intervals, their ratio, the paired outcomes, success per visual parameter,
    and videos with the camera's view beside the scene."""
    m = evaluate(
        _cfg(
            f"ckpt={student}",
            "visual=heldout",
            "episodes=4",
            "video_episodes=1",
            "tensorboard=false",
            f"out_dir={tmp_path / 'e'}",
        )
    )
    out = tmp_path / "e"
    t = m["teacher"]
    assert t["path"] == str(TEACHER)
    s_rate, t_rate = m["success_at_end"], t["success_at_end"]
    assert t_rate["episodes"] == 4 and t_rate["ci95"][0] <= t_rate["rate"] <= t_rate["ci95"][1]
    ratio = s_rate["rate"] / t_rate["rate"] if t_rate["successes"] else None
    assert t["student_over_teacher"] == ratio
    assert sum(t["paired"].values()) == 4
    assert t["paired"]["both"] + t["paired"]["student_only"] == s_rate["successes"]
    assert t["paired"]["both"] + t["paired"]["teacher_only"] == t_rate["successes"]
    assert m["visual_label"] == "heldout (trained on default)"
    assert m["config"]["env"]["sim"]["visual"] == "heldout"
    summary = (out / "summary.md").read_text()
    assert "teacher success at end, same episodes [95% Wilson]" in summary
    assert "student / teacher success at end" in summary and "heldout (trained on default)" in summary
    assert "## Success per visual parameter" in summary
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["teacher"] == t
    visual = saved["success_by_visual"]
    assert visual and all(k.startswith("visual_") for k in visual)
    assert not any(k.startswith("visual_") for k in saved["success_by_parameter"])
    assert (out / "success_by_visual.png").is_file()
    rows = list(csv.DictReader(open(out / "episodes.csv")))
    assert [int(r["teacher_success_at_end"]) for r in rows].count(1) == t_rate["successes"]
    hues = [float(r["visual_object_hue"]) for r in rows]
    assert all(0.75 <= h <= 0.95 for h in hues)  # the held-out hues, never the training ones
    # The video: the 320x240 scene, a 4 px gap, the 64x64 depth image upscaled to 240x240.
    from PIL import Image

    gif = Image.open(next(out.glob("episode_000_seed_0.*")))
    assert gif.size[0] == 320 + 4 + 240


def test_the_teacher_faces_the_students_episodes(student: Path) -> None:
    """The teacher runs in the camera env reading ``privileged``: the same episodes as the student
    (the same physics draws per seed), and the same outcome as in an env without a camera."""
    source = prepare("checkpoint", str(student))
    teacher = prepare_teacher("auto", source)
    assert teacher.privileged and teacher.env_cfg == source.env_cfg
    students = run_episodes(source, episodes=2, base_seed=3)
    teachers = run_episodes(teacher, episodes=2, base_seed=3)
    assert [r.randomization for r in students] == [r.randomization for r in teachers]
    plain = prepare("checkpoint", str(TEACHER))  # its own env: joint_delta, no camera
    alone = run_episodes(plain, episodes=2, base_seed=3)
    assert [(r.episode_return, r.outcome) for r in alone] == [(r.episode_return, r.outcome) for r in teachers]


def test_teacher_options(student: Path, tmp_path: Path) -> None:
    source = prepare("checkpoint", str(student))
    assert prepare_teacher("none", source) is None
    assert prepare_teacher(str(TEACHER), source).ckpt_path == str(TEACHER)
    run = make_run(tmp_path)  # an ee_delta state policy
    state = prepare("checkpoint", str(run))
    assert prepare_teacher("auto", state) is None  # a state policy has no teacher
    with pytest.raises(
        EvaluationError,
        match="teacher=.*only a camera policy is compared with a teacher, "
        r"this is a state policy \(\d+ state values\)",
    ):
        prepare_teacher(str(TEACHER), state)
    with pytest.raises(EvaluationError, match="control.mode='ee_delta' in the teacher, 'joint_delta' here"):
        prepare_teacher(str(run), source)
    with pytest.raises(EvaluationError, match="teacher=.*nowhere.pt: missing checkpoint"):
        prepare_teacher(str(tmp_path / "nowhere.pt"), source)
    gone = make_student(tmp_path, name="orphan.pt", teacher=str(tmp_path / "moved.pt"))
    with pytest.raises(
        EvaluationError,
        match="teacher=auto: the checkpoint's teacher .*moved.pt does not exist here; give teacher=",
    ):
        prepare_teacher("auto", prepare("checkpoint", str(gone)))
    with pytest.raises(EvaluationError, match="the teacher must be a state policy"):
        prepare_teacher(str(student), source)


def test_a_policy_and_an_env_of_the_other_kind_are_refused(student: Path, tmp_path: Path) -> None:
    """One line naming the policy and the env, whichever way round; images that differ too."""
    cfg = _cfg(f"ckpt={student}", "cameras=none")
    with pytest.raises(EvaluationError) as info:
        prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, None, OmegaConf.to_container(cfg.env))
    line = str(info.value)
    assert "\n" not in line and "is a camera policy (depth [1, 64, 64] + 29 state values)" in line
    assert "the env has no camera (env.camera=null): drop cameras=none" in line
    run = make_run(tmp_path)
    cfg = _cfg(f"ckpt={run}", "cameras=wrist_depth")
    with pytest.raises(
        EvaluationError,
        match=r"is a state policy \(\d+ state values\) and the env has a "
        r"camera \(env.camera=\{mount: wrist, modality: depth, "
        r"64x64\}\): use cameras=none",
    ):
        prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, None, OmegaConf.to_container(cfg.env))
    cfg = _cfg(f"ckpt={student}", "cameras=wrist_rgb")
    with pytest.raises(
        EvaluationError,
        match=r"image mismatch: checkpoint reads depth \[1, 64, 64\], "
        r"env gives rgb \[3, 64, 64\]",
    ):
        prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, None, OmegaConf.to_container(cfg.env))


def test_one_camera_key_changes_only_that_key(student: Path) -> None:
    """env.camera.fov=60 keeps the checkpoint's mount and modality."""
    cfg = _cfg(f"ckpt={student}", "++env.camera.fov=60")
    source = prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, None, OmegaConf.to_container(cfg.env))
    assert source.env_cfg["camera"] == {"mount": "wrist", "modality": "depth", "fov": 60}


def test_the_scripted_baseline_reads_the_privileged_state(tmp_path: Path) -> None:
    """In a camera env the scripted expert acts as in the env without one: same episodes, same returns."""
    args = ("policy=scripted", "episodes=2", *QUIET, f"outputs_root={tmp_path}")
    with_camera = evaluate(_cfg(*args, "cameras=fixed_rgb", "visual=default", "name=cam"))
    plain = evaluate(_cfg(*args, "name=plain"))
    assert with_camera["return"] == plain["return"] and with_camera["outcomes"] == plain["outcomes"]
    assert with_camera["camera_label"] == "{mount: fixed, modality: rgb}"
    assert "teacher" not in with_camera


# --- what the videos show ------------------------------------------------------------------------
def test_depth_view_colours_and_upscaling() -> None:
    depth = np.array([[[0.0, 0.02], [0.51, 1.0]]], np.float32)
    image = depth_image(depth, near=0.02, far=1.0)
    assert image.shape == (2, 2, 3) and image.dtype == np.uint8
    assert (image[0, 0] == 0).all()  # a missing pixel is black
    assert image[0, 1].sum() > image[1, 1].sum()  # near is brighter than far
    big = upscale(image, 240)
    assert big.shape == (240, 240, 3) and (big[:120, :120] == image[0, 0]).all()
    assert (big[120:, 120:] == image[1, 1]).all()
    rgb = np.zeros((3, 2, 4), np.uint8)
    rgb[0] = 200  # red
    view = camera_view({"depth": depth, "rgb": rgb, "state": np.zeros(3)}, 0.02, 1.0)
    assert view.shape == (2, 2 + 4, 3) and (view[:, 2:, 0] == 200).all() and (view[:, 2:, 1:] == 0).all()
    frame = beside(np.zeros((240, 320, 3), np.uint8), view)
    assert frame.shape == (240, 320 + 4 + 720, 3)
    assert camera_view(np.zeros(5), 0.02, 1.0) is None
    # stacked frames (env.camera.frames=2): the view shows the newest image of each
    stacked = camera_view(
        {
            "depth": np.concatenate([np.full_like(depth, 0.9), depth]),
            "rgb": np.concatenate([np.full_like(rgb, 50), rgb]),
        },
        0.02,
        1.0,
    )
    np.testing.assert_array_equal(stacked, view)


# --- export ---------------------------------------------------------------------------------------
def _export_cfg(*overrides: str):
    register_export_config()
    return compose_config("export", list(overrides))


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
@pytest.mark.parametrize(
    "modality, model", [("depth", MODEL), ("rgbd", KEYPOINTS)], ids=["depth", "rgbd-keypoints"]
)
def test_export_a_camera_policy(tmp_path: Path, modality: str, model: dict) -> None:
    """Every format gives the checkpoint policy's actions on observations recorded from the camera
    env, and the JSON names each input with its shape and dtype (RGB uint8)."""
    pytest.importorskip("onnxruntime")
    ckpt_path = make_student(tmp_path, modality=modality, model=model)
    results = export(_export_cfg(f"ckpt={ckpt_path}", "format=all", "verify_obs=300"))
    shapes = {"observation": ["batch", 29], "depth": ["batch", 1, 64, 64], "rgb": ["batch", 3, 64, 64]}
    dtypes = {"observation": "float32", "depth": "float32", "rgb": "uint8"}
    names = ["observation", "depth"] + (["rgb"] if modality == "rgbd" else [])
    for fmt, r in results.items():
        meta = json.loads(Path(r["json"]).read_text())
        assert r["max_abs_action_diff"] <= meta["verification"]["tolerance"] == 1e-4, (fmt, r)
        assert [i["name"] for i in meta["inputs"]] == names and "input" not in meta
        for i in meta["inputs"]:
            assert i["shape"] == shapes[i["name"]] and i["dtype"] == dtypes[i["name"]]
        assert meta["inputs"][0]["env_key"] == "state"
        assert meta["camera"]["mount"] == "wrist" and meta["camera"]["modality"] == modality
        assert max(stop for _, stop in meta["observation_layout"].values()) == 29
        assert meta["env_kwargs"]["camera"] == {"mount": "wrist", "modality": modality}
        assert meta["checkpoint"]["kind"] == "vision"


def test_exported_camera_policy_acts_as_the_checkpoint(tmp_path: Path) -> None:
    """The recorded observations span the action box, and the file gives the checkpoint's actions
    whether fed one observation at a time or a batch (rgb as uint8)."""
    ckpt_path = make_student(tmp_path, modality="rgb")
    ckpt = torch.load(ckpt_path, weights_only=True)
    recorded, reference = record(ckpt, 120, seed=0)
    assert list(recorded) == ["observation", "rgb"] and recorded["rgb"].dtype == np.uint8
    assert recorded["rgb"].shape == (120, 3, 64, 64) and (np.abs(reference) > 0.999).any()
    assert np.ptp(reference, axis=0).min() > 0.1  # the actions depend on what is seen
    results = export(_export_cfg(f"ckpt={ckpt_path}", "format=torchscript", "verify=false"))
    policy = load_exported(results["torchscript"]["path"])
    batch = policy({k: v[:20] for k, v in recorded.items()})
    np.testing.assert_allclose(batch, reference[:20], atol=1e-4)


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_example_drives_the_camera_env_with_the_file(tmp_path: Path) -> None:
    """examples/run_exported_policy.py feeds the camera env's dict observation to the file, without
    rlgrasp's training code or TorchRL."""
    ckpt_path = make_student(tmp_path)
    out = tmp_path / "deploy" / "student.pt2"
    export(_export_cfg(f"ckpt={ckpt_path}", "format=pt2", f"out={out}", "verify=false"))
    probe = (
        "import runpy, sys; sys.argv = ['x', sys.argv[1], '1'];"
        f"runpy.run_path({str(ROOT / 'examples' / 'run_exported_policy.py')!r}, run_name='__main__');"
        "bad = [m for m in sys.modules if m.startswith(('rlgrasp.train', 'rlgrasp.evaluation', 'torchrl'))];"
        "assert not bad, bad"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe, str(out)], capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "success " in done.stdout and "/1 " in done.stdout


def test_export_refuses_a_camera_checkpoint_that_does_not_fit_its_env(tmp_path: Path) -> None:
    path = make_student(tmp_path)
    ckpt = torch.load(path, weights_only=True)
    ckpt["spec"]["images"] = {"rgb": [3, 64, 64]}
    torch.save(ckpt, path)
    with pytest.raises(ExportError, match=r"image mismatch: checkpoint reads rgb \[3, 64, 64\], env gives"):
        export(_export_cfg(f"ckpt={path}", "format=pt2"))
    assert not (tmp_path / "export").exists()


# --- enjoy -------------------------------------------------------------------------------------
def _enjoy_cfg(*overrides: str):
    register_enjoy_config()
    return compose_config("enjoy", list(overrides))


class RecordingClient:
    """Stands in for a GUI client: records the visualizer calls."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def configureDebugVisualizer(self, flag: int, value: int) -> None:  # noqa: N802 - PyBullet's name
        self.calls.append(("flag", flag, value))

    def resetDebugVisualizerCamera(self, *args) -> None:  # noqa: N802
        self.calls.append(("camera", *args))


@pytest.mark.parametrize("modality, rgb, depth", [("depth", 0, 1), ("rgb", 1, 0), ("rgbd", 1, 1)])
def test_enjoy_shows_the_camera_preview_panes(modality: str, rgb: int, depth: int) -> None:
    import pybullet

    env = env_factory({**asdict(EnvConfig()), "camera": {"mount": "wrist", "modality": modality}})()
    try:
        client = RecordingClient()
        set_up_gui(env, client)
        flags = {flag: value for kind, flag, value, *_ in client.calls if kind == "flag"}
        assert flags[pybullet.COV_ENABLE_GUI] == 1
        assert flags[pybullet.COV_ENABLE_RGB_BUFFER_PREVIEW] == rgb
        assert flags[pybullet.COV_ENABLE_DEPTH_BUFFER_PREVIEW] == depth
        viewer = ViewerConfig()  # the GUI looks where the videos do: the env's default viewer
        assert client.calls[-1] == ("camera", viewer.distance, viewer.yaw, viewer.pitch, list(VIEWER_TARGET))
        assert camera_line(env).startswith(f"camera: wrist {modality} 64x64; the GUI's preview panes")
    finally:
        env.close()
    plain = env_factory(asdict(EnvConfig()))()
    try:
        assert gui_settings(plain) == [(pybullet.COV_ENABLE_GUI, 0)] and camera_line(plain) is None
    finally:
        plain.close()


def test_enjoy_plays_a_camera_policy_headless(student: Path) -> None:
    lines: list[str] = []
    results = play(
        _enjoy_cfg(f"ckpt={student}", "episodes=1", "speed=0", "render=none", "visual=heldout"),
        out=lines.append,
    )
    assert lines[1].startswith("camera: wrist depth 64x64")
    assert lines[-1] == f"success {int(results[0].success_at_end)}/1"
    assert 0.75 <= results[0].randomization["visual_object_hue"] <= 0.95
    with pytest.raises(EvaluationError, match="is a camera policy .* and the env has no camera"):
        play(_enjoy_cfg(f"ckpt={student}", "render=none", "cameras=none"), out=lines.append)


@pytest.mark.slow
def test_camera_evaluation_does_not_depend_on_the_worker_count(student: Path, tmp_path: Path) -> None:
    """Student and teacher in spawned workers: the same figures as in this process."""
    out = {}
    for w in (1, 2):
        m = evaluate(
            _cfg(
                f"ckpt={student}",
                "episodes=6",
                f"workers={w}",
                "video_episodes=1",
                "tensorboard=false",
                f"out_dir={tmp_path / str(w)}",
            )
        )
        out[w] = {
            k: v
            for k, v in m.items()
            if k not in ("timing", "config", "output_dir", "summary_markdown", "files")
        }
    assert out[1] == out[2] and out[1]["teacher"]["success_at_end"]["episodes"] == 6
