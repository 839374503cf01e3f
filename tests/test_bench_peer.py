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


# --- TQC with HER on panda-gym (--algo tqc): sb3-contrib's TQC and SB3's HerReplayBuffer ------------
@pytest.fixture
def contrib():
    """sb3-contrib and panda-gym, or the test skips (the `peer` and `panda` extras)."""
    pytest.importorskip("panda_gym")
    return pytest.importorskip("sb3_contrib")


def test_sb3_gets_panda_pick_place_tqc_her_settings(peer, train_cfg, contrib) -> None:
    """TQC: SAC's mapping with the quantiles; HER as SB3's HerReplayBuffer (0.8 relabelled: 4 sampled
    goals, future) on the same goal env read as its Dict; sb3-contrib builds its TQC from them."""
    from stable_baselines3 import HerReplayBuffer
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from rlgrasp.envs.factory import env_factory

    cfg = train_cfg("experiment=panda_pick_place_tqc_her", "algo.replay.buffer_frames=4096")
    a, c = cfg.algo, cfg.collector
    assert peer["sb3_algo"](cfg) == "TQC" and peer["sb3_class"](cfg) is contrib.TQC
    kw = peer["sb3_kwargs"](cfg)
    envs = peer["n_envs"](cfg)
    assert kw["train_freq"] == (c.steps_per_env, "step") and kw["gradient_steps"] == envs * c.steps_per_env
    assert (kw["batch_size"], kw["gamma"], kw["tau"], kw["learning_rate"]) == (2048, 0.95, 0.05, 1e-3)
    assert kw["top_quantiles_to_drop_per_net"] == a.loss.top_quantiles_to_drop_per_net == 2
    assert kw["replay_buffer_class"] is HerReplayBuffer
    assert kw["replay_buffer_kwargs"] == {"n_sampled_goal": 4, "goal_selection_strategy": "future"}
    assert kw["learning_starts"] == envs * 50  # every env's first episode ended: SB3 samples no other
    assert peer["sb3_env_cfg"](cfg)["observation"] == "dict"

    venv = VecNormalize(
        DummyVecEnv([env_factory(peer["sb3_env_cfg"](cfg))] * envs), **peer["vecnorm_kwargs"](cfg)
    )
    assert not venv.norm_obs  # RL Zoo does not normalize this task's observations, nor does rlgrasp here
    model = contrib.TQC("MultiInputPolicy", venv, seed=0, device="cpu", **kw)
    assert model.critic.n_quantiles == a.loss.n_quantiles and model.critic.n_critics == a.loss.num_critics
    for q in model.critic.q_networks:
        widths = [layer.out_features for layer in q if isinstance(layer, torch.nn.Linear)]
        assert widths == [*a.critic.hidden_sizes, a.loss.n_quantiles]
    widths = [layer.out_features for layer in model.actor.latent_pi if isinstance(layer, torch.nn.Linear)]
    assert widths == list(cfg.model.hidden_sizes) == [512, 512, 512]
    assert float(model.log_ent_coef.detach().exp()) == pytest.approx(a.loss.alpha_init)
    assert model.replay_buffer.n_sampled_goal == 4
    venv.close()


def test_tqc_her_unmatched_names_the_differences(peer, train_cfg, contrib) -> None:
    notes = "\n".join(peer["unmatched"](train_cfg("experiment=panda_pick_place_tqc_her")))
    for named in (
        "SB3's TQC a state-dependent one",
        "only from finished episodes",
        "starts after 400 frames",
    ):
        assert named in notes, named
    odd = "\n".join(
        peer["unmatched"](train_cfg("experiment=panda_pick_place_tqc_her", "algo.her.relabel_ratio=0.7"))
    )
    assert "n_sampled_goal=2 relabels 0.667" in odd


def test_her_on_rlgrasps_own_task_is_refused_for_the_sb3_side(peer, train_cfg) -> None:
    with pytest.raises(ValueError, match="env=gym"):
        peer["sb3_kwargs"](train_cfg("experiment=pick_place_sac_her"))


def test_algo_chooses_the_experiment_and_env_id_needs_a_gym_one(peer) -> None:
    from argparse import Namespace

    assert peer["EXPERIMENTS"]["tqc"] == "panda_pick_place_tqc_her"
    args = Namespace(experiment="grasp_sac", seed=0, overrides=[], algo="tqc", env_id=None)
    with pytest.raises(SystemExit, match="--algo tqc: experiment=grasp_sac trains algo=sac"):
        peer["checked_config"](args, ["rlgrasp"])
    args = Namespace(experiment="grasp_sac", seed=0, overrides=[], algo=None, env_id="X-v0")
    with pytest.raises(SystemExit, match="not an env=gym experiment"):
        peer["checked_config"](args, ["rlgrasp"])


def test_both_curves_are_printed_at_the_same_frames(peer, capsys) -> None:
    results = {
        "rlgrasp": {"evals": [(1.0, 1024, 0.25, 32), (2.0, 2048, 0.5, 100)]},
        "sb3": {"evals": [(1.5, 1024, 0.125, 32), (3.0, 2048, 0.75, 32), (3.5, 2176, 0.75, 100)]},
    }
    assert peer["by_frames"](results) == [(1024, 0.25, 0.125), (2048, 0.5, 0.75), (2176, None, 0.75)]
    peer["print_by_frames"](results, 0)
    assert "     2,176        -    0.750" in capsys.readouterr().out


@pytest.mark.full
def test_the_tqc_her_side_runs_a_few_frames_on_reach(peer, train_cfg, contrib, tmp_path) -> None:
    """The SB3 side end to end on tiny settings: sb3-contrib's TQC with HER on PandaReach-v3's Dict in
    two env processes, evaluated by rlgrasp's Evaluator on the flat env (the SB3 policy reading the same
    values as its Dict); one periodic and the final evaluation reach the curve file."""
    import json

    cfg = train_cfg(
        "experiment=panda_pick_place_tqc_her",
        "env.id=panda_gym:PandaReach-v3",
        "collector.num_workers=1",
        "collector.envs_per_worker=2",
        "collector.steps_per_env=25",
        "total_frames=300",
        "algo.replay.buffer_frames=1000",
        "algo.optim.batch_size=32",
        "algo.optim.utd_ratio=0.1",
        "model.hidden_sizes=[16,16]",
        "algo.critic.hidden_sizes=[16,16]",
        "eval.interval_frames=150",
        "eval.episodes=2",
        "eval.final_episodes=2",
        "eval.num_envs=2",
    )
    out = tmp_path / "sb3.json"
    peer["run_sb3"](cfg, out)
    evals = json.loads(out.read_text())["evals"]
    assert [frames for _, frames, _, _ in evals] == [150, 300] and all(0 <= s <= 1 for _, _, s, _ in evals)
