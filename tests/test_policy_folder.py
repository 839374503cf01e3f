"""Policy folders (model.safetensors + config.json + model card): a .pt policy converted acts exactly as
the .pt, the shipped folder evaluates, and a folder with a missing, extra or misshapen tensor, a link,
or a config naming a class outside the registry is refused in one line naming it."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from rlgrasp.compose import compose_config, compose_eval
from rlgrasp.evaluation.cli import evaluate
from rlgrasp.evaluation.policies import CheckpointActor
from rlgrasp.export import ExportError, check_folder_request, export, record, register_export_config
from rlgrasp.policy_file import CheckpointError, load_checkpoint, read_checkpoint

st = pytest.importorskip("safetensors.torch")

ROOT = Path(__file__).resolve().parents[1]
PT = ROOT / "policies" / "grasp_ppo.pt"
FOLDER = ROOT / "policies" / "grasp_ppo"
NORM_MEAN = "module.0.module.norm.mean"
FIRST = "module.0.module.mlp.0.weight"


def _export(*overrides: str) -> dict:
    register_export_config()
    return export(compose_config("export", list(overrides)))


def _copy(tmp: Path) -> Path:
    folder = tmp / "grasp_ppo"
    shutil.copytree(FOLDER, folder)
    return folder


def _refused(folder: Path, match: str) -> str:
    """The folder is refused by every reader, in one line matching ``match``."""
    with pytest.raises(CheckpointError, match=match) as info:
        read_checkpoint(folder)
    message = str(info.value)
    assert "\n" not in message and str(folder) in message
    with pytest.raises(CheckpointError, match=match):
        load_checkpoint(folder)
    return message


def test_a_converted_pt_acts_exactly_as_the_pt(tmp_path: Path) -> None:
    """.pt -> folder -> checkpoint dict: the same tensors, the same config, and the very same actions on
    20 observations of the policy's own episodes (bit for bit: the same module, the same weights)."""
    out = tmp_path / "converted"
    result = _export(f"ckpt={PT}", "format=folder", f"out={out}", "verify_obs=20")
    assert result["folder"]["max_abs_action_diff"] == 0.0
    assert sorted(p.name for p in out.iterdir()) == ["README.md", "config.json", "model.safetensors"]
    pt, folder = read_checkpoint(PT), read_checkpoint(out)
    assert folder.keys() - {"run_dir"} >= pt.keys() - {"run_dir"}
    for key in ("spec", "frames", "updates", "best_eval_success", "last_eval", "versions"):
        assert folder[key] == pt[key], key
    for key in ("env", "model", "experiment_name", "seed"):
        assert folder["config"][key] == pt["config"][key], key
    assert folder["config"]["algo"]["_target_"] == pt["config"]["algo"]["_target_"]
    assert pt["actor"].keys() == folder["actor"].keys()
    for key, tensor in pt["actor"].items():
        assert folder["actor"][key].dtype == tensor.dtype and torch.equal(folder["actor"][key], tensor), key
    observations, reference = record(pt, 20, seed=0)
    actor = CheckpointActor(folder, deterministic=True)
    actions = np.stack([actor(obs) for obs in observations["observation"]])
    assert np.array_equal(actions, reference)
    # The shipped folder is this conversion of the shipped .pt (not a stale copy).
    shipped = st.load_file(str(FOLDER / "model.safetensors"))
    assert shipped.keys() == pt["actor"].keys()
    assert all(torch.equal(shipped[k], v) for k, v in pt["actor"].items())


def test_the_shipped_folder_evaluates_as_its_pt(tmp_path: Path) -> None:
    """rlgrasp-eval ckpt=policies/grasp_ppo episodes=2: the same episodes as the .pt's."""
    common = ("episodes=2", "workers=1", "video=false", "plots=false", f"outputs_root={tmp_path}")
    folder = evaluate(compose_eval([f"ckpt={FOLDER}", *common, "name=folder"]))
    pt = evaluate(compose_eval([f"ckpt={PT}", *common, "name=pt"]))
    assert folder["checkpoint"]["kind"] == "folder" and folder["checkpoint"]["frames"] == 270336
    assert folder["success_at_end"] == pt["success_at_end"] and folder["return"] == pt["return"]


def test_a_folder_exports_like_its_pt(tmp_path: Path) -> None:
    result = _export(f"ckpt={FOLDER}", "format=torchscript", f"out={tmp_path}", "verify_obs=10")
    meta = json.loads(Path(result["torchscript"]["json"]).read_text())
    assert result["torchscript"]["max_abs_action_diff"] <= 1e-5 and len(meta["checkpoint"]["sha256"]) == 64


def test_missing_extra_and_misshapen_tensors_are_refused(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    weights = folder / "model.safetensors"
    tensors = st.load_file(str(weights))
    st.save_file({k: v for k, v in tensors.items() if k != NORM_MEAN}, str(weights))
    _refused(
        folder, f"refused: model.safetensors has no tensor '{NORM_MEAN}', which the model of config.json"
    )
    st.save_file({**tensors, "extra.weight": torch.zeros(3)}, str(weights))
    _refused(folder, "holds the tensor 'extra.weight', which the model of config.json does not have")
    st.save_file({**tensors, FIRST: torch.zeros(256, 48)}, str(weights))
    _refused(folder, rf"tensor '{FIRST}' has shape \[256, 48\], the model of config.json needs \[256, 49\]")
    st.save_file({**tensors, FIRST: tensors[FIRST].double()}, str(weights))
    _refused(folder, f"tensor '{FIRST}' is F64, the model of config.json needs float32")
    st.save_file({**tensors, FIRST: tensors[FIRST] * float("nan")}, str(weights))
    _refused(folder, f"{FIRST} holds 12,544 NaN")
    weights.write_bytes(b"\x00garbage" * 10)
    _refused(folder, "unreadable model.safetensors")


def test_a_symlink_in_the_folder_is_refused(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    elsewhere = tmp_path / "elsewhere.json"
    shutil.move(folder / "config.json", elsewhere)
    (folder / "config.json").symlink_to(elsewhere)
    _refused(folder, "config.json is a symlink .*never through a link")
    link = tmp_path / "link"
    link.symlink_to(_copy(tmp_path / "b"))
    _refused(link, "is a symlink")


def test_a_config_naming_a_class_outside_the_registry_is_refused(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    path = folder / "config.json"
    good = json.loads(path.read_text())
    bad = json.loads(path.read_text())
    bad["config"]["env"]["_target_"] = "os.system"
    path.write_text(json.dumps(bad))
    _refused(folder, r"config.env._target_='os.system' is not a part rlgrasp builds at env")
    bad = json.loads(json.dumps(good))
    bad["config"]["model"]["_target_"] = "os.system"
    path.write_text(json.dumps(bad))
    _refused(folder, r"config.model._target_ would be called when the config is built")
    for key, value, match in (
        ("format_version", 2, "format_version 2; this rlgrasp reads 1 to 1"),
        ("kind", "audio", "kind='audio': must be one of"),
        ("frames", -1, "frames=-1 is not a whole number"),
    ):
        path.write_text(json.dumps({**good, key: value}))
        _refused(folder, match)
    path.write_text(json.dumps({**good, "best_eval_success": float("nan")}))  # Python's json writes NaN
    _refused(folder, "unreadable config.json .*NaN is not a JSON number")


def test_without_safetensors_a_folder_names_the_extra(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "safetensors", None)
    monkeypatch.setitem(sys.modules, "safetensors.torch", None)
    _refused(FOLDER, r'needs the safetensors package: pip install -e "\.\[policy\]"')
    with pytest.raises(ExportError, match=r"format=folder needs the safetensors package: .*\[policy\]"):
        check_folder_request(tmp_path / "new")


def test_export_never_replaces_a_folder_that_is_not_a_policy_folder(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    with pytest.raises(ExportError, match="exists and is not a policy folder"):
        _export(f"ckpt={PT}", "format=folder", f"out={mine}", "verify=false")
    assert (mine / "notes.txt").read_text() == "keep me"


def test_the_model_card_names_the_env_and_the_algorithm() -> None:
    text = (FOLDER / "README.md").read_text()
    assert text.startswith("---\n")
    card = yaml.safe_load(text.split("---\n")[1])
    assert card["library_name"] == "rlgrasp"
    assert {"reinforcement-learning", "robotics", "pybullet", "ppo", "panda", "lift"} <= set(card["tags"])
    (result,) = card["model-index"][0]["results"]
    assert result["dataset"]["type"] == "rlgrasp/PandaGrasp-v0" and "lift cube" in result["dataset"]["name"]
    metrics = {m["type"]: m["value"] for m in result["metrics"]}
    assert metrics["success_rate"] == 0.92
    assert "rlgrasp-eval ckpt=" in text
    meta = json.loads((FOLDER / "config.json").read_text())
    assert meta["config"]["env"]["control"]["mode"] == "joint_delta"  # today's nested shape
    assert meta["config"]["algo"] == {"name": "ppo"} and len(meta["interface"]["action_meaning"]) == 8


@pytest.mark.parametrize(
    ("robot", "label"), [("kuka_iiwa", "kuka_iiwa"), ({"name": "mine", "model": "a.urdf"}, "mine")]
)
def test_the_model_card_names_the_arm_however_the_config_gives_it(robot, label) -> None:
    """Today's configs give the arm as a name (``robot: kuka_iiwa``), a user's arm as a mapping: the card
    names it either way (it read ``robot.name`` only, and wrote "the `None` arm" for a name)."""
    from rlgrasp.policy_folder import card_metadata, model_card

    meta = {
        "config": {"env": {"robot": robot, "randomization": "default"}, "algo": {"name": "sac"}},
        "kind": "state",
        "interface": {"control_hz": 20},
        "spec": {"obs_dim": 46, "action_dim": 5},
        "source": {"file": "p.pt", "sha256": "0" * 64},
    }
    assert {label, "sac", "lift"} <= set(card_metadata(meta, "p")["tags"])
    assert f"`{label}` arm" in model_card(meta, "p")


def test_the_docs_read_a_folder_without_rlgrasp(monkeypatch) -> None:
    """docs/export.md's numpy reader of the shipped folder acts as rlgrasp does (to float32 rounding)."""
    text = (ROOT / "docs" / "export.md").read_text()
    (code,) = [b for b in text.split("```python\n")[1:] if "def act(obs)" in b]
    monkeypatch.chdir(ROOT)  # the snippet names policies/grasp_ppo/ from the repository root
    namespace: dict = {}
    exec(code.split("```")[0], namespace)
    observations, reference = record(read_checkpoint(FOLDER), 20, seed=0)
    actions = np.stack([namespace["act"](obs) for obs in observations["observation"]])
    np.testing.assert_allclose(actions, reference, atol=1e-6)
    assert namespace["config"]["spec"]["obs_dim"] == observations["observation"].shape[1]


def test_a_camera_policy_converts_with_its_images_and_teacher(tmp_path: Path) -> None:
    """A camera student: its images in the spec, its teacher named, the same actions on its own
    episodes (the export's check reads the folder back and compares on 10 camera observations)."""
    pt = ROOT / "policies" / "grasp_vision_depth.pt"
    result = _export(f"ckpt={pt}", "format=folder", f"out={tmp_path / 'v'}", "verify_obs=10")
    assert result["folder"]["max_abs_action_diff"] == 0.0
    folder = read_checkpoint(tmp_path / "v")
    assert folder["kind"] == "vision" and folder["spec"] == read_checkpoint(pt)["spec"]
    assert folder["config"]["algo"]["teacher"] == "policies/grasp_ppo.pt"
    card = yaml.safe_load((tmp_path / "v" / "README.md").read_text().split("---\n")[1])
    assert {"vision", "distill"} <= set(card["tags"])
