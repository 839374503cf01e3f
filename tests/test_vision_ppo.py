"""PPO from pixels with an asymmetric critic (``experiment=grasp_vision_ppo``): the camera actor reads
proprioception and the wrist depth image, the critic the privileged state; a run checkpoints a camera
policy that evaluation and export rebuild, and resumes."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from rlgrasp.policy_file import load_checkpoint, policy_from_checkpoint
from rlgrasp.train.loop import train
from rlgrasp.train.parts import PRIVILEGED_KEY, build_parts

#: Two batches of two workers x two envs x 256 steps, with a quick evaluation.
SMALL_VISION_PPO = (
    "experiment=grasp_vision_ppo",
    "total_frames=2048",
    "time_budget_min=null",
    "collector.envs_per_worker=2",
    "collector.steps_per_env=256",
    "algo.optim.epochs=1",
    "algo.optim.minibatch_size=256",
    "eval.interval_frames=1024",
    "eval.episodes=2",
    "eval.final_episodes=2",
    "eval.num_envs=2",
    "checkpoint.interval_frames=1024",
    "logger=none",
)


def _norm_count(weights: dict[str, torch.Tensor]) -> float:
    (count,) = [v for k, v in weights.items() if k.endswith("norm.count")]
    return float(count)


def test_the_critic_reads_the_privileged_state_through_its_own_normalizer(train_cfg) -> None:
    parts = build_parts(train_cfg(*SMALL_VISION_PPO))
    assert set(parts.actor.in_keys) == {"observation", "depth"}
    assert parts.critic.in_keys == [PRIVILEGED_KEY]
    assert set(parts.norms) == {"observation", PRIVILEGED_KEY}
    assert parts.norms["observation"].mean.shape == (parts.spec["obs_dim"],)
    assert parts.norms[PRIVILEGED_KEY].mean.shape == (parts.spec["privileged_dim"],)
    assert parts.kind == "vision"


def test_a_state_run_keeps_one_shared_normalizer(train_cfg) -> None:
    parts = build_parts(train_cfg("experiment=smoke"))
    assert parts.kind == "state" and list(parts.norms) == ["observation"]
    assert parts.critic.in_keys == ["observation"] and parts.norms["observation"] is parts.norm


@pytest.mark.full  # camera PPO, rendered images on workers
def test_vision_ppo_checkpoints_a_camera_policy_and_resumes(tmp_path: Path, train_cfg) -> None:
    run = tmp_path / "run"
    success = train(train_cfg(*SMALL_VISION_PPO, run_dir=run))
    assert 0.0 <= success <= 1.0
    ckpt = load_checkpoint(run)
    assert ckpt["kind"] == "vision" and ckpt["frames"] == 2048
    assert ckpt["spec"]["images"] == {"depth": [1, 64, 64]}
    assert ckpt["spec"]["privileged_dim"] > ckpt["spec"]["obs_dim"]
    # Both normalizers learned from every trained frame: the actor's from the proprioception, the
    # critic's from the privileged state.
    assert _norm_count(ckpt["actor"]) == _norm_count(ckpt["ppo"]["critic"]) == 2048

    policy = policy_from_checkpoint(ckpt)
    assert set(policy.in_keys) == {"observation", "depth"}
    state, depth = torch.zeros(3, ckpt["spec"]["obs_dim"]), torch.full((3, 1, 64, 64), 0.3)
    obs = TensorDict({"observation": state, "depth": depth}, [3])
    a1, a2 = policy(obs.clone())["action"], policy(obs.clone())["action"]
    assert a1.shape == (3, ckpt["spec"]["action_dim"]) and torch.equal(a1, a2)

    train(train_cfg(*SMALL_VISION_PPO, f"resume={run}", "total_frames=3072", run_dir=run))
    resumed = load_checkpoint(run)
    assert resumed["kind"] == "vision" and resumed["frames"] == 3072 and resumed["generation"] == 1
    assert resumed["updates"] == ckpt["updates"] + 1
    assert _norm_count(resumed["ppo"]["critic"]) == 3072
