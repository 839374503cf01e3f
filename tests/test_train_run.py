"""End-to-end runs of the training pipeline on small budgets (real env, process collector)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from rlgrasp.train.checkpoint import load_checkpoint, policy_from_checkpoint
from rlgrasp.train.config import register_configs
from rlgrasp.train.loop import TrainingError, train

CONFIG_DIR = str(Path(__file__).resolve().parents[1] / "configs")
# Developing without the grasp env: RLGRASP_TEST_ENV=pendulum (no success signal then).
ENV = os.environ.get("RLGRASP_TEST_ENV", "grasp")

REQUIRED_TAGS = {
    "charts/episodic_return",
    "charts/episodic_length",
    "charts/SPS",
    "charts/learning_rate",
    "losses/policy_loss",
    "losses/value_loss",
    "losses/entropy",
    "losses/approx_kl",
    "losses/clipfrac",
    "losses/explained_variance",
    "losses/grad_norm",
    "eval/mean_reward",
    "time/collect_s",
    "time/train_s",
}
SUCCESS_TAGS = {"charts/success_rate", "eval/success_rate"}


def _cfg(run_dir: Path, *overrides: str):
    register_configs()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(
            config_name="train",
            overrides=[f"env={ENV}", "experiment=smoke", f"paths.output_dir={run_dir}", *overrides],
        )


def _scalars(run_dir: Path) -> EventAccumulator:
    acc = EventAccumulator(str(run_dir / "tensorboard"), size_guidance={"scalars": 0})
    acc.Reload()
    return acc


def test_smoke_end_to_end_then_resume(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    success = train(_cfg(run_dir))
    assert isinstance(success, float)
    tags = set(_scalars(run_dir).Tags()["scalars"])
    required = REQUIRED_TAGS | (SUCCESS_TAGS if ENV == "grasp" else set())
    assert required <= tags, required - tags
    ckpts = run_dir / "checkpoints"
    assert (ckpts / "last.pt").is_file() and (ckpts / "best.pt").is_file()
    assert len(list(ckpts.glob("ckpt_*.pt"))) <= 2  # keep_last
    log_text = (run_dir / "train.log").read_text()
    assert log_text.count("frames") > 0
    if ENV == "grasp":  # the final evaluation runs eval.final_episodes (8 in smoke), not 4
        assert re.search(r"final eval: success \d/8 \[95% Wilson", log_text), log_text[-800:]

    ckpt = load_checkpoint(run_dir)
    assert ckpt["frames"] == 2048
    assert {"actor", "critic", "optimizer", "obs_norm", "rng", "config", "versions", "spec"} <= set(ckpt)
    assert float(ckpt["obs_norm"]["count"]) > 0
    policy = policy_from_checkpoint(ckpt)
    obs = torch.zeros(3, ckpt["spec"]["obs_dim"])
    from tensordict import TensorDict

    a1 = policy(TensorDict({"observation": obs}, [3]))["action"]
    a2 = policy(TensorDict({"observation": obs}, [3]))["action"]
    assert a1.shape == (3, ckpt["spec"]["action_dim"])
    assert torch.equal(a1, a2)  # deterministic

    # resume: same run dir, frames and curves continue
    train(_cfg(run_dir, f"resume={run_dir}", "total_frames=4096"))
    assert load_checkpoint(run_dir)["frames"] == 4096
    steps = [e.step for e in _scalars(run_dir).Scalars("losses/policy_loss")]
    assert steps == sorted(steps) and steps[-1] == 4096 and 2048 in steps


def _first_losses(run_dir: Path) -> list[float]:
    acc = _scalars(run_dir)
    return [acc.Scalars(t)[0].value for t in ("losses/policy_loss", "losses/value_loss")]


def test_same_seed_same_first_losses_one_worker(tmp_path: Path) -> None:
    over = ["collector.num_workers=1", "total_frames=512", "seed=3"]
    train(_cfg(tmp_path / "a", *over))
    train(_cfg(tmp_path / "b", *over))
    assert _first_losses(tmp_path / "a") == _first_losses(tmp_path / "b")


@pytest.mark.parametrize("collector", ["process", "single"])
def test_crashing_env_stops_with_a_clear_error(tmp_path: Path, collector: str) -> None:
    inner = "rlgrasp.envs:PandaGraspEnv" if ENV == "grasp" else "rlgrasp.train.standin:make_pendulum_gym"
    cfg = _cfg(
        tmp_path,
        f"collector={collector}",
        "env.gym_factory=rlgrasp.train.standin:make_crashing_gym",
        "+env.kwargs.crash_after=300",
        f"+env.kwargs.gym_factory={inner}",
        "total_frames=100000",
    )
    with pytest.raises(TrainingError) as info:
        train(cfg)
    message = str(info.value)
    assert "worker 0 env" in message and "deliberate crash after 300 steps" in message, message
    assert (tmp_path / "checkpoints" / "last.pt").is_file()
