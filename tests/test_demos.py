"""Demonstrations: the file's round trip and its refusals, behaviour cloning, DAPG's decaying
weight, and a short PPO run that learns from a file, logs it, checkpoints and resumes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.algos.ppo.schema import ImitationTermConfig
from rlgrasp.compose import compose_config, compose_train
from rlgrasp.demos.bc import Imitation, decayed_weight, pretrain
from rlgrasp.demos.cli import _objects_line, record_demos
from rlgrasp.demos.dataset import DemoError, demos_for, layout_of, load_demos, write_demos
from rlgrasp.envs.factory import env_factory
from rlgrasp.models.mlp import MLPConfig, build_models
from rlgrasp.train.loop import Trainer
from rlgrasp.train.resume import prepare_run
from tests.helpers import SMOKE_IN_PROCESS, demo_env_cfg, demo_files, logged_scalars, ppo_algo


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """Three episodes of the scripted expert on the cube, recorded in this process."""
    out = tmp_path_factory.mktemp("demos") / "cube"
    cfg = compose_config("demos", ["episodes=3", f"out={out}", "workers=1", "keep=all"])
    info = record_demos(cfg)
    assert info["episodes"] == 3 and info["kept"] == 3
    return out / "demos"


def test_demonstrations_are_recorded_with_the_arm_training_names() -> None:
    """``robot=`` picks the arm as in training, so demonstrations match the run that reads them."""
    assert compose_config("demos", ["out=x"]).env.robot == "panda"
    assert compose_config("demos", ["out=x", "robot=xarm6"]).env.robot == "xarm6"


def _layout(control_mode: str = "ee_delta") -> dict:
    env_cfg = demo_env_cfg(control_mode)
    env = env_factory(env_cfg)()
    try:
        return layout_of(env, env_cfg)
    finally:
        env.close()


def test_the_file_round_trips_with_its_summary(recorded: Path) -> None:
    demos = load_demos(recorded, _layout())
    meta = json.loads((recorded / "demos.json").read_text())
    n = meta["summary"]["frames"]
    assert demos.frames.batch_size == torch.Size([n])
    assert demos.frames["observation"].shape == (n, meta["obs_dim"])
    assert demos.frames["action"].shape == (n, meta["action_dim"])
    assert int(demos.frames["done"].sum()) == 3  # one end per episode
    assert meta["control_mode"] == "ee_delta" and meta["summary"]["objects"]
    # the expert's actions are what the env was given: inside the action box
    assert float(demos.frames["action"].abs().max()) <= 1.0
    # load from the out directory too (the path rlgrasp-demos prints is the demos directory)
    assert load_demos(recorded.parent, _layout()).frames.numel() == n


def test_the_console_names_each_object_only_for_a_few() -> None:
    few = {f"primitives/{k}": {"success": 1, "episodes": 1} for k in ("box", "sphere")}
    many = {f"random_urdfs/{i:03d}": {"success": 1, "episodes": 1} for i in range(200)}
    assert "primitives/box" in _objects_line(few, "demos/x")
    assert _objects_line(many, "demos/x") == "200 objects (success per object: demos/x/summary.json)"


def test_returns_are_discounted_within_each_episode(recorded: Path) -> None:
    demos = load_demos(recorded, _layout())
    returns = demos.returns(0.5)
    reward, done = demos.frames["reward"], demos.frames["done"]
    last = done.nonzero().flatten()
    assert torch.allclose(returns[last], reward[last])
    i = int(last[0]) - 1
    assert torch.isclose(returns[i], reward[i] + 0.5 * returns[i + 1])


def test_foreign_missing_and_empty_files_are_refused(tmp_path: Path) -> None:
    files = demo_files(tmp_path)
    with pytest.raises(DemoError, match="recorded with control_mode='joint_delta', this run has 'ee_delta'"):
        load_demos(files["foreign_demos"], _layout())
    with pytest.raises(DemoError, match="holds no demonstrations"):
        load_demos(files["empty_demos"], _layout())
    with_cells = _layout()
    with_cells["obs_slices"] = {**with_cells["obs_slices"], "object_cells": [46, 110]}
    with pytest.raises(DemoError, match="this run's state has object_cells, the recording's not") as refused:
        load_demos(files["empty_demos"], with_cells)  # the layout is checked before the episodes
    assert "\n" not in str(refused.value) and "[46, 110]" not in str(refused.value)
    with pytest.raises(DemoError, match="no such file or directory"):
        load_demos(tmp_path / "nowhere", _layout())
    with pytest.raises(DemoError, match="not a demonstration directory"):
        load_demos(tmp_path, _layout())
    layout = _layout()
    failed = {  # every entry a learner reads, in its dtype and width: only the successes are missing
        "observation": torch.zeros(2, layout["obs_dim"]),
        "action": torch.zeros(2, layout["action_dim"]),
        "reward": torch.zeros(2),
        "done": torch.zeros(2, dtype=torch.bool),
        "success": torch.zeros(2, dtype=torch.bool),
    }
    failures = TensorDict(failed, [2])
    write_demos(tmp_path / "failed", failures, {**layout, "summary": {"kept": 1}})
    with pytest.raises(DemoError, match="none of its 1 episodes succeeded"):
        load_demos(tmp_path / "failed", _layout())


def test_behaviour_cloning_lowers_its_loss_on_a_fixed_set(recorded: Path) -> None:
    torch.manual_seed(0)
    demos = load_demos(recorded, _layout())
    model = OmegaConf.structured(MLPConfig(hidden_sizes=[64, 64]))
    actor, critic, norm = build_models(demos.meta["obs_dim"], -torch.ones(4), torch.ones(4), model)
    algo = ppo_algo(bc_epochs=8, demos=str(recorded))
    out = pretrain(actor, critic, norm, demos, algo.pretrain, algo.loss.gamma)
    assert out["pretrain/bc_loss_last"] < 0.5 * out["pretrain/bc_loss_first"]
    assert out["pretrain/value_loss_last"] < out["pretrain/value_loss_first"]


def test_the_demo_weight_decays_as_configured(recorded: Path) -> None:
    term = OmegaConf.structured(ImitationTermConfig(coeff=0.5, decay=0.9))
    weights = [decayed_weight(term, k) for k in range(5)]
    assert weights[0] == pytest.approx(0.5) and weights[3] == pytest.approx(0.5 * 0.9**3)
    assert all(a > b for a, b in zip(weights, weights[1:]))
    flat = OmegaConf.structured(ImitationTermConfig(coeff=0.5, decay=1.0))
    assert decayed_weight(flat, 100) == pytest.approx(0.5)
    model = OmegaConf.structured(MLPConfig(hidden_sizes=[16]))
    demos = load_demos(recorded, _layout())
    actor, _, _ = build_models(demos.meta["obs_dim"], -torch.ones(4), torch.ones(4), model)
    term = Imitation(actor, demos, term, torch.device("cpu"))
    assert term.start(TensorDict({}, []), 2)["charts/demo_weight"] == pytest.approx(0.5 * 0.81)
    loss, values = term.loss(TensorDict({}, []))
    assert loss.requires_grad
    assert float(loss.detach()) == pytest.approx(0.5 * 0.81 * values["bc_loss"], rel=1e-5)


def test_ppo_with_demos_logs_checkpoints_and_resumes(recorded: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    args = [
        *SMOKE_IN_PROCESS,
        f"algo.demos={recorded}",
        "algo.pretrain.epochs=1",
        "algo.terms.imitation.decay=0.5",
        f"paths.output_dir={run}",
    ]
    cfg, resumed = prepare_run(compose_train(args))
    trainer = Trainer(cfg, resumed=resumed)
    seen = logged_scalars(trainer)
    trainer.run()
    assert seen["charts/demo_weight"] == pytest.approx([0.1, 0.05])
    assert len(seen["losses/bc_loss"]) == 2 and "pretrain/bc_loss_first" in seen
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert state["config"]["algo"]["demos"] == str(recorded)  # referenced, not copied
    assert not any(p.name.endswith(".memmap") for p in run.rglob("*"))
    resume = compose_train([*args, f"resume={run}", "total_frames=384"])
    cfg, resumed = prepare_run(resume, {"resume", "total_frames"})
    again = Trainer(cfg, resumed=resumed)
    seen = logged_scalars(again)
    again.run()
    assert again.updates == 3 and seen["charts/demo_weight"] == pytest.approx([0.1 * 0.5**2])
    assert "pretrain/bc_loss_first" not in seen  # pre-training belongs to the fresh start only


def test_behaviour_cloning_alone_starts_no_workers(recorded: Path, tmp_path: Path) -> None:
    args = [
        *SMOKE_IN_PROCESS,
        f"algo.demos={recorded}",
        "algo.pretrain.epochs=1",
        "algo.pretrain.only=true",
        f"paths.output_dir={tmp_path / 'bc'}",
    ]
    trainer = Trainer(prepare_run(compose_train(args))[0])
    trainer.run()
    assert trainer.frames == 0 and (tmp_path / "bc" / "checkpoints" / "last.pt").is_file()


def test_a_moved_file_is_refused_before_training(recorded: Path, tmp_path: Path) -> None:
    moved = tmp_path / "moved"
    shutil.copytree(recorded, moved / "demos")
    args = [
        *SMOKE_IN_PROCESS,
        "env.control.mode=joint_delta",
        f"algo.demos={moved}",
        f"paths.output_dir={tmp_path / 'r'}",
    ]
    with pytest.raises(DemoError, match="control_mode='ee_delta', this run has 'joint_delta'"):
        cfg = prepare_run(compose_train(args))[0]
        demos_for(cfg.algo.demos, env_factory(cfg.env), cfg.env)
