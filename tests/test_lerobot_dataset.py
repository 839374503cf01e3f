"""LeRobot datasets: rlgrasp's demonstrations written as one, read by LeRobot's own loader, and read
back into a folder ``algo.demos=`` loads, frames and actions equal; a malformed dataset refused in one
line. The checks against LeRobot's loader skip where lerobot is not installed (it pins an older torch
than this project: docs/sparse.md#lerobot-datasets)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from rlgrasp.compose import compose_config
from rlgrasp.demos.cli import record_demos
from rlgrasp.demos.dataset import demo_transitions, layout_of, load_demos, write_demos
from rlgrasp.envs.factory import env_factory
from tests.helpers import demo_env_cfg

pytest.importorskip("pyarrow", reason="the lerobot extra (pyarrow) is not installed")
from rlgrasp.demos.lerobot import LeRobotError, export_demos, import_dataset, main  # noqa: E402

REPO_ID = "local/rlgrasp_test"


def _layout(*overrides: str) -> dict:
    env_cfg = demo_env_cfg("ee_delta", *overrides)
    env = env_factory(env_cfg)()
    try:
        return {**layout_of(env, env_cfg), "env": env_cfg}
    finally:
        env.close()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """Two episodes of the scripted expert on the cube, both kept (a failure too, if one fails)."""
    out = tmp_path_factory.mktemp("demos") / "cube"
    record_demos(compose_config("demos", ["episodes=2", f"out={out}", "workers=1", "keep=all"]))
    return out / "demos"


@pytest.fixture(scope="module")
def exported(recorded: Path, tmp_path_factory) -> Path:
    dst = tmp_path_factory.mktemp("lerobot") / "cube"
    export_demos(recorded, dst)
    return dst


@pytest.fixture
def lerobot(monkeypatch, tmp_path):
    """LeRobot's dataset class, offline (no hub at run time), or a skip saying why."""
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_LEROBOT_HOME", str(tmp_path / "hf_lerobot"))
    module = pytest.importorskip(
        "lerobot.datasets.lerobot_dataset",
        reason="lerobot is not installed (it pins torch<2.11; test it in a virtualenv of its own)",
    )
    return module.LeRobotDataset


def _equal(a: TensorDict, b: TensorDict) -> None:
    keys = sorted(a.keys(include_nested=True, leaves_only=True), key=str)
    assert keys == sorted(b.keys(include_nested=True, leaves_only=True), key=str)
    for key in keys:
        assert a[key].dtype == b[key].dtype, key
        assert torch.equal(a[key], b[key]), key


def test_demos_round_trip_through_a_lerobot_dataset(recorded: Path, exported: Path, tmp_path: Path) -> None:
    """Export, import, load as a run does: every entry equal, the meta and the transitions too."""
    info = json.loads((exported / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 20  # 12 substeps of 1/240 s
    assert {"observation.state", "action", "next.reward", "next.done"} <= set(info["features"])
    back = import_dataset(exported, tmp_path / "back")
    layout = _layout()
    original, imported = load_demos(recorded, layout), load_demos(back, layout)
    _equal(original.frames, imported.frames)
    assert imported.meta["summary"]["kept"] == original.meta["summary"]["kept"]
    env_cfg = layout["env"]
    _equal(demo_transitions(original, env_cfg), demo_transitions(imported, env_cfg))
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())  # no partial folder left


def test_lerobots_loader_reads_the_exported_frames(recorded: Path, exported: Path, lerobot) -> None:
    frames = load_demos(recorded, _layout()).frames
    dataset = lerobot(REPO_ID, root=exported)
    assert len(dataset) == frames.numel() and dataset.num_episodes == int(frames["done"].sum())
    rows = dataset.hf_dataset[:]
    state, action = torch.stack(rows["observation.state"]), torch.stack(rows["action"])
    assert torch.equal(state, frames["observation"]) and torch.equal(action, frames["action"])
    assert torch.equal(torch.stack(rows["next.reward"]), frames["reward"])
    assert torch.equal(torch.stack(rows["next.done"]), frames["done"])
    item = dataset[3]  # LeRobot's own item path: its frame and the timestamp at the control rate
    assert torch.equal(item["observation.state"], frames["observation"][3])
    assert float(item["timestamp"]) == pytest.approx(float(item["frame_index"]) / 20)


def test_a_dataset_lerobot_wrote_imports_into_demos(lerobot, tmp_path: Path) -> None:
    """A dataset recorded elsewhere (no rlgrasp meta) imports against the env given for it: the last
    step of each episode has no successor there, so the run leaves it out."""
    layout = _layout()
    obs_dim, act_dim = layout["obs_dim"], layout["action_dim"]
    features = {
        "observation.state": {"dtype": "float32", "shape": (obs_dim,), "names": None},
        "action": {"dtype": "float32", "shape": (act_dim,), "names": None},
        "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
        "next.done": {"dtype": "bool", "shape": (1,), "names": None},
    }
    dataset = lerobot.create(REPO_ID, fps=20, features=features, root=tmp_path / "theirs", use_videos=False)
    rng = np.random.default_rng(0)
    states, actions = rng.normal(size=(7, obs_dim)).astype(np.float32), rng.uniform(-1, 1, (7, act_dim))
    for start, stop in ((0, 4), (4, 7)):
        for t in range(start, stop):
            dataset.add_frame(
                {
                    "observation.state": states[t],
                    "action": actions[t].astype(np.float32),
                    "next.reward": np.array([t / 10], np.float32),
                    "next.done": np.array([t == stop - 1]),
                    "task": "lift",
                }
            )
        dataset.save_episode()
    dataset.finalize()
    with pytest.raises(LeRobotError, match="has no meta/rlgrasp.json"):
        import_dataset(tmp_path / "theirs", tmp_path / "mine")
    frames = load_demos(import_dataset(tmp_path / "theirs", tmp_path / "mine", layout), layout).frames
    assert torch.equal(frames["observation"], torch.from_numpy(states))
    assert torch.equal(frames["action"], torch.from_numpy(actions.astype(np.float32)))
    assert frames["episode"].tolist() == [0] * 4 + [1] * 3 and bool(frames["success"].all())
    assert demo_transitions(load_demos(tmp_path / "mine", layout), layout["env"]).numel() == 5


def _camera_demos(root: Path) -> tuple[Path, dict]:
    """A camera env's demonstrations without recording: random images and states of its shapes."""
    layout = _layout("cameras=wrist_rgbd", "model=cnn")
    rng = np.random.default_rng(1)
    n, entries = 6, {}
    shapes = {"observation": [layout["obs_dim"]], **layout["images"], "privileged": [5]}
    for key, shape in shapes.items():
        for name in (key, f"next_{key}"):
            if key == "rgb":
                entries[name] = torch.from_numpy(rng.integers(0, 256, (n, *shape), dtype=np.uint8))
            else:
                entries[name] = torch.from_numpy(rng.uniform(0, 2, (n, *shape)).astype(np.float32))
    entries.update(
        action=torch.rand(n, layout["action_dim"]),
        reward=torch.rand(n),
        done=torch.tensor([False, False, True, False, False, True]),
        terminated=torch.tensor([False, False, True, False, False, False]),
        success=torch.tensor([True] * 3 + [False] * 3),
        episode=torch.tensor([0, 0, 0, 1, 1, 1]),
    )
    meta = {k: v for k, v in layout.items()}
    meta["summary"] = {"kept": 2}
    return write_demos(root, TensorDict(entries, [n]), meta), layout


def test_camera_images_round_trip(tmp_path: Path, request) -> None:
    """An rgb image travels as LeRobot's camera image (PNG, lossless), depth and the next frames as
    arrays: all equal after the round trip, and in LeRobot's loader where it is installed."""
    demos, layout = _camera_demos(tmp_path / "cam")
    export_demos(demos, tmp_path / "dataset")
    info = json.loads((tmp_path / "dataset/meta/info.json").read_text())
    assert info["features"]["observation.images.rgb"]["dtype"] == "image"
    assert info["features"]["next.observation.images.rgb"]["dtype"] == "uint8"
    back = import_dataset(tmp_path / "dataset", tmp_path / "back")
    original = load_demos(demos, layout).frames
    _equal(original, load_demos(back, layout).frames)
    try:
        lerobot = request.getfixturevalue("lerobot")
    except pytest.skip.Exception:
        return
    item = lerobot(REPO_ID, root=tmp_path / "dataset")[4]
    assert torch.equal((item["observation.images.rgb"] * 255).round().to(torch.uint8), original["rgb"][4])
    assert torch.equal(item["observation.depth"], original["depth"][4])


def _mangle_info(root: Path, change) -> None:
    path = root / "meta/info.json"
    info = json.loads(path.read_text())
    change(info)
    path.write_text(json.dumps(info))


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (
            lambda i: i["features"]["observation.state"].update(dtype="float16"),
            "features['observation.state'].dtype='float16' (allowed: float32, float64, int64",
        ),
        (lambda i: i.update(codebase_version="v2.1"), "codebase_version='v2.1' (read: 'v3.0'"),
        (lambda i: i["features"]["action"].update(shape=[2]), "column 'action': a row of length"),
        (lambda i: i["features"]["next.reward"].update(dtype="video"), "dtype='video' (allowed:"),
        (lambda i: i.update(total_frames=3), "total_frames=3, the data files hold"),
    ],
)
def test_a_malformed_dataset_is_refused_in_one_line(exported: Path, tmp_path: Path, change, said) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(exported, bad)
    _mangle_info(bad, change)
    before = sorted((p.relative_to(bad), p.stat().st_size) for p in bad.rglob("*"))
    with pytest.raises(LeRobotError) as caught:
        import_dataset(bad, tmp_path / "out")
    message = str(caught.value)
    assert said in message and "\n" not in message
    assert not (tmp_path / "out").exists()
    assert sorted((p.relative_to(bad), p.stat().st_size) for p in bad.rglob("*")) == before  # only read


def test_a_link_inside_a_dataset_is_refused(exported: Path, tmp_path: Path) -> None:
    bad = tmp_path / "linked"
    shutil.copytree(exported, bad)
    os.symlink(tmp_path, bad / "data" / "elsewhere")
    with pytest.raises(LeRobotError, match="is a symlink"):
        import_dataset(bad, tmp_path / "out")


def test_the_command_line_refuses_an_existing_target_in_one_line(
    recorded: Path, exported: Path, capsys
) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["export", str(recorded), str(exported)])
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err


def test_the_command_line_imports_a_dataset_without_rlgrasp_meta_against_the_env_it_composes(
    recorded: Path, exported: Path, tmp_path: Path, capsys
) -> None:
    """Without ``meta/rlgrasp.json`` the env comes from the command line (here the demos config's
    default, the recording's); env overrides for a dataset that records its env are refused."""
    with pytest.raises(SystemExit) as caught:
        main(["import", str(exported), str(tmp_path / "x"), "robot=xarm6"])
    assert caught.value.code == 2 and "records its env" in capsys.readouterr().err
    theirs = tmp_path / "theirs"
    shutil.copytree(exported, theirs)
    (theirs / "meta/rlgrasp.json").unlink()
    main(["import", str(theirs), str(tmp_path / "mine")])
    layout = _layout()
    original, imported = load_demos(recorded, layout).frames, load_demos(tmp_path / "mine", layout).frames
    _equal(original, imported)
