"""benchmarks/bench_peer.py's mapping from an rlgrasp training config to Stable-Baselines3's PPO: the
peer comparison is only fair if SB3 gets rlgrasp's settings, and SB3 must accept them as given."""

import runpy
from pathlib import Path

import gymnasium as gym
import pytest
import torch

sb3 = pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def peer():
    return runpy.run_path(str(ROOT / "benchmarks" / "bench_peer.py"))


def test_sb3_gets_grasp_ppo_settings(peer, train_cfg):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # optional: skipped without it

    cfg = train_cfg("experiment=grasp_ppo")
    a, m, c = cfg.algo, cfg.model, cfg.collector
    kw = peer["sb3_kwargs"](cfg)
    envs = peer["n_envs"](cfg)
    assert envs == c.num_workers * c.envs_per_worker
    assert envs * kw["n_steps"] == c.num_workers * c.envs_per_worker * c.steps_per_env
    assert (kw["batch_size"], kw["n_epochs"], kw["gamma"], kw["gae_lambda"]) == (
        a.minibatch_size, a.epochs, a.gamma, a.gae_lambda)
    assert (kw["clip_range"], kw["ent_coef"], kw["vf_coef"], kw["max_grad_norm"]) == (
        a.clip_epsilon, a.entropy_coeff, a.critic_coeff, a.max_grad_norm)
    assert 1.5 * kw["target_kl"] == pytest.approx(a.target_kl)  # SB3 stops at 1.5 x its target_kl

    # SB3 takes the keywords as they are; the networks, init std, optimizer and schedule come out as set.
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")] * envs), **peer["vecnorm_kwargs"](cfg))
    assert not venv.norm_reward and venv.clip_obs == m.obs_clip
    model = sb3.PPO("MlpPolicy", venv, seed=0, device="cpu", **kw)
    policy = model.policy
    for net in (policy.mlp_extractor.policy_net, policy.mlp_extractor.value_net):
        widths = [layer.out_features for layer in net if isinstance(layer, torch.nn.Linear)]
        assert widths == list(m.hidden_sizes)
    assert any(isinstance(layer, torch.nn.Tanh) for layer in policy.mlp_extractor.policy_net)
    assert torch.allclose(policy.log_std, torch.full_like(policy.log_std, m.init_log_std))
    assert policy.optimizer.defaults["eps"] == a.adam_eps
    # rlgrasp's lr_at: lr x (1 - frames / total_frames); SB3 passes that fraction left.
    assert model.lr_schedule(1.0) == pytest.approx(a.lr)
    assert model.lr_schedule(0.25) == pytest.approx(0.25 * a.lr)
    venv.close()
