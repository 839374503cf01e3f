"""benchmarks/bench_peer.py's mapping from an rlgrasp training config to Stable-Baselines3's PPO and
SAC: the peer comparison is only fair if SB3 gets rlgrasp's settings, and SB3 must accept them as given."""

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
    loss, o, m, c = cfg.algo.loss, cfg.algo.optim, cfg.model, cfg.collector
    kw = peer["sb3_kwargs"](cfg)
    envs = peer["n_envs"](cfg)
    assert envs == c.num_workers * c.envs_per_worker
    assert envs * kw["n_steps"] == c.num_workers * c.envs_per_worker * c.steps_per_env
    assert (kw["batch_size"], kw["n_epochs"], kw["gamma"], kw["gae_lambda"]) == (
        o.minibatch_size,
        o.epochs,
        loss.gamma,
        loss.gae_lambda,
    )
    assert (kw["clip_range"], kw["ent_coef"], kw["vf_coef"], kw["max_grad_norm"]) == (
        loss.clip_epsilon,
        loss.entropy_coeff,
        loss.critic_coeff,
        o.max_grad_norm,
    )
    assert 1.5 * kw["target_kl"] == pytest.approx(
        cfg.algo.schedule.target_kl
    )  # SB3 stops at 1.5 x its target_kl

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
    assert policy.optimizer.defaults["eps"] == o.adam_eps
    # rlgrasp's lr_at: lr x (1 - frames / total_frames); SB3 passes that fraction left.
    assert model.lr_schedule(1.0) == pytest.approx(o.lr)
    assert model.lr_schedule(0.25) == pytest.approx(0.25 * o.lr)
    venv.close()


def test_sb3_gets_grasp_sac_settings(peer, train_cfg):
    """SAC: one SB3 rollout per rlgrasp batch, as many gradient steps per frame, the same replay,
    temperature and networks; SB3 builds its SAC from the keywords as given."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # optional: skipped without it

    cfg = train_cfg("experiment=grasp_sac")
    a, m, c = cfg.algo, cfg.model, cfg.collector
    assert peer["sb3_algo"](cfg) == "SAC"
    kw = peer["sb3_kwargs"](cfg)
    envs = peer["n_envs"](cfg)
    assert envs * kw["train_freq"][0] == c.num_workers * c.envs_per_worker * c.steps_per_env
    assert kw["train_freq"] == (c.steps_per_env, "step")
    # grasp_sac: 8 envs x 16 steps = 128 frames a rollout, x 0.25 = 32 gradient steps, exactly.
    assert (
        kw["gradient_steps"] == a.optim.utd_ratio * envs * c.steps_per_env == 64
    )  # grasp_sac: 0.5 steps a frame
    assert (kw["batch_size"], kw["buffer_size"], kw["learning_starts"]) == (
        a.optim.batch_size,
        a.replay.buffer_frames,
        a.replay.learning_starts,
    )
    assert (kw["gamma"], kw["tau"], kw["learning_rate"], kw["target_update_interval"]) == (
        a.loss.gamma,
        a.loss.tau,
        a.optim.actor_lr,
        1,
    )

    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")] * envs), **peer["vecnorm_kwargs"](cfg))
    model = sb3.SAC("MlpPolicy", venv, seed=0, device="cpu", **kw)
    assert model.gradient_steps / (envs * model.train_freq.frequency) == a.optim.utd_ratio
    assert float(model.log_ent_coef.detach().exp()) == pytest.approx(a.loss.alpha_init)
    assert model.target_entropy == -venv.action_space.shape[0]  # target_entropy null: -(action size)
    widths = [layer.out_features for layer in model.actor.latent_pi if isinstance(layer, torch.nn.Linear)]
    assert widths == list(m.hidden_sizes)
    assert any(isinstance(layer, torch.nn.Tanh) for layer in model.actor.latent_pi)
    assert len(model.critic.q_networks) == a.loss.num_critics
    for q in model.critic.q_networks:
        widths = [layer.out_features for layer in q if isinstance(layer, torch.nn.Linear)]
        assert widths == [*a.critic.hidden_sizes, 1]
    for opt in (model.actor.optimizer, model.critic.optimizer, model.ent_coef_optimizer):
        assert opt.param_groups[0]["lr"] == pytest.approx(a.optim.actor_lr)
    venv.close()


def test_sac_ratio_rounds_to_whole_steps(peer, train_cfg):
    """SB3 takes a whole number of gradient steps per rollout: the nearest one, named as unmatched;
    a ratio that rounds to none is refused (SB3 would never train)."""
    cfg = train_cfg("experiment=grasp_sac", "algo.optim.utd_ratio=0.3")
    assert peer["sb3_kwargs"](cfg)["gradient_steps"] == 38  # 0.3 x 128 = 38.4
    assert any("38.4 gradient steps" in note for note in peer["unmatched"](cfg))
    assert not any("utd_ratio" in note for note in peer["unmatched"](train_cfg("experiment=grasp_sac")))
    with pytest.raises(ValueError, match="0 gradient steps"):
        peer["sb3_kwargs"](train_cfg("experiment=grasp_sac", "algo.optim.utd_ratio=0.001"))


def test_sac_unmatched_names_the_differences(peer, train_cfg):
    notes = "\n".join(
        peer["unmatched"](
            train_cfg("experiment=grasp_sac", "algo.optim.critic_lr=1e-3", "algo.optim.actor_every=2")
        )
    )
    named_all = (
        "state-independent std",
        "model.min_std=0.05",
        "algo.optim.critic_lr=0.001",
        "layer_norm",
        "algo.critic.activation=relu",
        "algo.optim.actor_every=2",
        "uniformly at random",
        "collector.overlap",
    )
    for named in named_all:
        assert named in notes, named
    assert "target_kl" not in notes  # PPO's notes stay PPO's
    plain = "\n".join(
        peer["unmatched"](
            train_cfg(
                "experiment=grasp_sac",
                "algo.critic.layer_norm=false",
                "algo.critic.activation=tanh",
                "collector.overlap=false",
            )
        )
    )
    for absent in ("LayerNorm", "critic.activation", "learning rates", "actor_every", "overlap"):
        assert absent not in plain, absent


def test_sac_with_demonstrations_is_refused(peer, train_cfg):
    with pytest.raises(ValueError, match="algo.demos"):
        peer["sb3_kwargs"](train_cfg("experiment=grasp_sac", "algo.demos=some/demos"))
