"""Export for deployment: every format gives the checkpoint policy's actions on recorded observations,
the JSON describes the vectors, the standalone example runs the file without rlgrasp's training code."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from rlgrasp.compose import compose_config
from rlgrasp.export import DeployPolicy, ExportError, export, register_export_config
from tests.helpers import make_run

ROOT = Path(__file__).resolve().parents[1]


def _cfg(*overrides: str):
    register_export_config()
    return compose_config("export", list(overrides))


def _spread_run(tmp: Path) -> Path:
    """A checkpoint whose actions spread over the whole box, saturating tanh on some entries (the
    freshly initialized policy acts near zero, which would hide a wrong squashing)."""
    run = make_run(tmp)
    path = run / "checkpoints" / "best.pt"
    ckpt = torch.load(path, weights_only=False)
    gen = torch.Generator().manual_seed(0)
    for key, value in ckpt["actor"].items():
        if key.endswith("weight"):  # a unit-gain layer; the last one 8x for actions at the bounds
            gain = 8.0 if key == "module.0.module.mlp.4.weight" else 1.0
            ckpt["actor"][key] = torch.randn(value.shape, generator=gen) * gain / value.shape[1] ** 0.5
    torch.save(ckpt, path)
    return run


def test_every_format_matches_the_checkpoint_on_1000_observations(tmp_path: Path) -> None:
    pytest.importorskip("onnxruntime")
    run = _spread_run(tmp_path)
    results = export(_cfg(f"ckpt={run}", "format=all", "verify_obs=1000"))
    assert set(results) == {"torchscript", "onnx", "pt2"}
    for fmt, r in results.items():
        assert Path(r["path"]).parent == run / "export"
        assert r["max_abs_action_diff"] <= 1e-5, (fmt, r)
        meta = json.loads(Path(r["json"]).read_text())
        assert meta["verification"]["observations"] == 1000 and meta["verification"]["tolerance"] == 1e-5
        assert (
            meta["inputs"]
            == [{"name": "observation", "env_key": None, "dtype": "float32", "shape": meta["input"]["shape"]}]
            and "camera" not in meta
        )
        obs_dim, act_dim = meta["input"]["shape"][1], meta["output"]["shape"][1]
        stops = sorted(stop for _, stop in meta["observation_layout"].values())
        assert stops[-1] == obs_dim and len(meta["action_meaning"]) == act_dim
        assert meta["control_mode"] == meta["env_kwargs"]["control"]["mode"] == "ee_delta"
        assert "_target_" not in meta["env_kwargs"] and meta["versions"]["export"]["torch"]


def test_recorded_actions_saturate_and_batching_changes_nothing(tmp_path: Path) -> None:
    """The check is meaningful (some actions at the bounds), and one batch = one call per observation."""
    from rlgrasp.export import deploy_module, input_specs, load_exported, record, write_format

    run = _spread_run(tmp_path)
    ckpt = torch.load(run / "checkpoints" / "best.pt", weights_only=False)
    recorded, reference = record(ckpt, 200, seed=0)
    obs = recorded["observation"]
    assert list(recorded) == ["observation"]  # a state policy: one input
    assert obs.shape == (200, ckpt["spec"]["obs_dim"]) and (np.abs(reference) > 0.999).any()
    path = write_format(deploy_module(ckpt), "pt2", tmp_path / "p.pt2", input_specs(ckpt["spec"]))
    policy = load_exported(path)
    one_by_one = np.stack([policy(o[None])[0] for o in obs[:20]])
    np.testing.assert_allclose(one_by_one, policy(obs)[:20], atol=1e-5)
    np.testing.assert_allclose(one_by_one, reference[:20], atol=1e-5)


def test_bounds_other_than_unit_box_match_tanh_normal() -> None:
    """Scaling into asymmetric bounds follows TorchRL's TanhNormal deterministic sample."""
    from tensordict import TensorDict
    from torchrl.envs import ExplorationType, set_exploration_type

    from rlgrasp.models.mlp import RunningNorm, build_actor

    model = OmegaConf.create(
        {"hidden_sizes": [8], "activation": "tanh", "min_std": 0.05, "init_log_std": -0.5}
    )
    low, high = torch.tensor([-2.0, 0.0, -0.5]), torch.tensor([2.0, 1.0, 3.0])
    norm = RunningNorm(5)
    norm.update(torch.randn(100, 5) * 3 + 1)
    actor = build_actor(norm, 5, low, high, model, deterministic=True)
    for p in actor.parameters():
        p.data.normal_(0, 2)
    obs = torch.randn(300, 5) * 4
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        want = actor(TensorDict({"observation": obs}, [300]))["action"]
    got = DeployPolicy(actor.module[0].module, low, high)(obs).detach()
    torch.testing.assert_close(got, want, atol=1e-6, rtol=0)


def test_a_gaussian_policy_exports_its_mean_clipped_to_the_bounds() -> None:
    """``model.distribution=normal``: the exported action is what the env executes, the actor's
    deterministic action (the mean, which may leave the bounds) clipped to them."""
    from tensordict import TensorDict
    from torchrl.envs import ExplorationType, set_exploration_type

    from rlgrasp.models.mlp import RunningNorm, build_actor

    model = OmegaConf.create(
        {
            "hidden_sizes": [8],
            "activation": "tanh",
            "min_std": 0.05,
            "init_log_std": -0.5,
            "distribution": "normal",
        }
    )
    low, high = torch.tensor([-2.0, 0.0, -0.5]), torch.tensor([2.0, 1.0, 3.0])
    actor = build_actor(RunningNorm(5), 5, low, high, model, deterministic=True)
    for p in actor.parameters():
        p.data.normal_(0, 2)
    obs = torch.randn(300, 5) * 4
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        mean = actor(TensorDict({"observation": obs}, [300]))["action"]
    assert ((mean < low) | (mean > high)).any()  # the clipping is exercised
    got = DeployPolicy(actor.module[0].module, low, high, squash=False)(obs).detach()
    torch.testing.assert_close(got, mean.clamp(low, high), atol=1e-6, rtol=0)


def test_bad_input_says_what(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="ckpt=.*required"):
        export(_cfg())
    with pytest.raises(ExportError, match="does not exist"):
        export(_cfg(f"ckpt={tmp_path / 'nope.pt'}"))
    run = make_run(tmp_path)
    with pytest.raises(ExportError, match="format=tflite: must be one of"):
        export(_cfg(f"ckpt={run}", "format=tflite"))
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ExportError, match="corrupt checkpoint"):
        export(_cfg(f"ckpt={tmp_path / 'junk.pt'}"))


@pytest.mark.full  # three interpreters; quick set: test_exits' export
def test_cli_and_example_run_without_training_code(tmp_path: Path) -> None:
    """``scripts/export.py`` writes where ``out=`` says; the example drives the env with the file and
    imports neither rlgrasp's training code nor TorchRL."""
    run = make_run(tmp_path)
    out = tmp_path / "deploy" / "grasp.pt2"
    cli = [
        sys.executable,
        str(ROOT / "scripts" / "export.py"),
        f"ckpt={run}",
        "format=pt2",
        f"out={out}",
        "verify_obs=100",
    ]
    done = subprocess.run(cli, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert out.is_file() and Path(f"{out}.json").is_file()
    probe = (
        "import runpy, sys; sys.argv = ['x', sys.argv[1], '2'];"
        f"runpy.run_path({str(ROOT / 'examples' / 'run_exported_policy.py')!r}, run_name='__main__');"
        "bad = [m for m in sys.modules if m.startswith(('rlgrasp.train', 'rlgrasp.evaluation', 'torchrl'))];"
        "assert not bad, bad"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe, str(out)], capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "success " in done.stdout and "/2 " in done.stdout
    bad = subprocess.run([*cli[:2], "ckpt=/no/such/run"], capture_output=True, text=True, cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines()[-1].startswith("error: missing checkpoint")


def test_output_paths(tmp_path: Path) -> None:
    from rlgrasp.export import output_paths

    run_ckpt = tmp_path / "run" / "checkpoints" / "best.pt"
    assert output_paths("onnx", None, run_ckpt) == {"onnx": tmp_path / "run" / "export" / "policy.onnx"}
    loose = tmp_path / "mine.pt"
    assert output_paths("pt2", None, loose) == {"pt2": tmp_path / "export" / "policy.pt2"}
    assert output_paths("pt2", str(tmp_path / "a.pt2"), loose) == {"pt2": tmp_path / "a.pt2"}
    every = output_paths("all", str(tmp_path / "out"), loose)
    assert every == {
        f: tmp_path / "out" / f"policy{ext}"
        for f, ext in (("torchscript", ".pt"), ("onnx", ".onnx"), ("pt2", ".pt2"))
    }


def test_a_failed_export_leaves_the_previous_one_and_no_temporary_file(tmp_path: Path, monkeypatch) -> None:
    """An export that fails its verification, or whose write fails (a full disk), used to replace the
    file it was to write (and its JSON): a deployment reading it then ran unverified actions."""
    import rlgrasp.export as export_module

    run = _spread_run(tmp_path)
    first = export(_cfg(f"ckpt={run}", "format=torchscript", "verify_obs=20"))["torchscript"]
    path, json_path = Path(first["path"]), Path(first["json"])
    before = {p: p.read_bytes() for p in (path, json_path)}
    ckpt_path = run / "checkpoints" / "best.pt"
    ckpt = torch.load(ckpt_path, weights_only=False)
    ckpt["actor"] = {k: v * 2 if k.endswith("weight") else v for k, v in ckpt["actor"].items()}
    torch.save(ckpt, ckpt_path)  # another policy: a new export would write other bytes

    monkeypatch.setattr(export_module, "max_abs_diff", lambda *args: 1.0)  # a mismatching file
    mismatch = r"differ from the checkpoint's by 1 > tolerance .*nothing was replaced"
    with pytest.raises(ExportError, match=mismatch):
        export(_cfg(f"ckpt={run}", "format=torchscript", "verify_obs=20"))
    assert {p: p.read_bytes() for p in (path, json_path)} == before
    assert sorted(p.name for p in path.parent.iterdir()) == sorted([path.name, json_path.name])

    def disk_full(module, f, *args, **kwargs):
        Path(f).write_bytes(b"PK" + b"\0" * 4096)  # some bytes went out
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(torch.jit, "save", disk_full)
    with pytest.raises(ExportError, match="No space left on device"):
        export(_cfg(f"ckpt={run}", "format=torchscript", "verify_obs=20"))
    assert {p: p.read_bytes() for p in (path, json_path)} == before
    assert sorted(p.name for p in path.parent.iterdir()) == sorted([path.name, json_path.name])
