"""Random Network Distillation: the intrinsic reward falls on states seen and stays high on new
ones, its returns ignore episode ends, its networks and statistics travel in checkpoints."""

from __future__ import annotations

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.algos.ppo.learner import PPOLearner
from rlgrasp.algos.ppo.rnd import INTRINSIC_REWARD, RND
from rlgrasp.compose import compose_train
from rlgrasp.models.mlp import MLPConfig, RunningNorm, build_models
from rlgrasp.train.loop import Trainer
from rlgrasp.train.resume import prepare_run
from tests.helpers import SMOKE_IN_PROCESS, logged_scalars, ppo_algo

OBS_DIM, ENVS, STEPS = 6, 4, 32


def _rnd(**algo) -> RND:
    torch.manual_seed(0)
    a = ppo_algo(rnd_coeff=1.0, **algo)
    return RND(OBS_DIM, RunningNorm(OBS_DIM), a.terms.rnd, a.loss)


def _batch(obs: torch.Tensor, next_obs: torch.Tensor) -> TensorDict:
    done = torch.zeros(ENVS, STEPS, 1, dtype=torch.bool)
    done[:, -1] = True
    return TensorDict(
        {
            "observation": obs,
            "next": {
                "observation": next_obs,
                "reward": torch.zeros(ENVS, STEPS, 1),
                "done": done,
                "terminated": done.clone(),
                "truncated": done.clone(),
            },
        },
        [ENVS, STEPS],
    )


def test_the_reward_shrinks_on_states_seen_and_not_on_new_ones() -> None:
    rnd = _rnd(rnd_update_fraction=1.0)
    seen = torch.randn(256, OBS_DIM)
    novel = torch.randn(256, OBS_DIM) * 3 + 4  # another region of the state space
    rnd.obs_rms.update(torch.cat([seen, novel]))  # the same whitening for both sets
    before_seen = float(rnd.novelty(seen).mean())
    optimizer = torch.optim.Adam(rnd.predictor.parameters(), lr=1e-3)
    for _ in range(300):
        loss = rnd.predictor_loss(TensorDict({"next": {"observation": seen}}, [256]))["loss_predictor"]
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    after_seen, after_novel = float(rnd.novelty(seen).mean()), float(rnd.novelty(novel).mean())
    assert after_seen < 0.2 * before_seen
    assert after_novel > 3 * after_seen


def test_intrinsic_advantages_join_ppos_across_episode_ends() -> None:
    rnd = _rnd(rnd_gamma=0.99)
    batch = _batch(torch.randn(ENVS, STEPS, OBS_DIM), torch.randn(ENVS, STEPS, OBS_DIM))
    metrics = rnd.start(batch, 0)
    assert metrics["charts/intrinsic_reward"] > 0 and batch[INTRINSIC_REWARD].shape == (ENVS, STEPS, 1)
    batch["advantage"] = torch.zeros(ENVS, STEPS, 1)
    with torch.no_grad():
        torch.nn.init.zeros_(rnd.value[-1].weight)
        torch.nn.init.zeros_(rnd.value[-1].bias)  # values 0: the advantage is the discounted reward sum
    rnd.after_gae(batch)
    reward, adv = batch[INTRINSIC_REWARD][0, :, 0], batch["advantage"][0, :, 0]
    lam = rnd.ppo_loss.gae_lambda * rnd.term.gamma
    expected = sum(reward[t] * lam**t for t in range(STEPS))
    # the env's done at the last step does not cut it; no episode end anywhere in between
    assert float(adv[0]) == pytest.approx(float(expected), rel=1e-4)


def test_rewards_are_scaled_by_the_spread_of_returns_carried_across_batches() -> None:
    rnd = _rnd(rnd_gamma=0.5)
    first = rnd._running_returns(torch.ones(2, 4))
    assert first[0].tolist() == [1.0, 1.5, 1.75, 1.875]
    assert rnd._running_returns(torch.ones(2, 1))[:, 0].tolist() == [1.9375, 1.9375]  # carried over
    rnd = _rnd(rnd_gamma=0.99)
    batch = _batch(torch.randn(ENVS, STEPS, OBS_DIM), torch.randn(ENVS, STEPS, OBS_DIM))
    rnd.start(batch, 0)
    errors = rnd.novelty(batch["next", "observation"])
    expected = errors / rnd.reward_rms.var.sqrt()
    assert torch.allclose(batch[INTRINSIC_REWARD][..., 0], expected)
    assert float(rnd.reward_rms.var) > 10 * float(errors.var())  # returns spread far wider


def test_the_learner_trains_rnd_and_checkpoints_round_trip() -> None:
    torch.manual_seed(0)
    model = OmegaConf.structured(MLPConfig(hidden_sizes=[16, 16]))
    algo = ppo_algo(minibatch_size=32, target_kl=None, rnd_coeff=0.5, epochs=2)
    actor, critic, norm = build_models(OBS_DIM, -torch.ones(2), torch.ones(2), model)
    rnd = RND(OBS_DIM, norm, algo.terms.rnd, algo.loss)
    learner = PPOLearner(actor, critic, norm, algo, torch.device("cpu"), extras=[rnd])
    obs = torch.randn(ENVS, STEPS, OBS_DIM)
    batch = _batch(obs, obs + 0.1)
    with torch.no_grad():
        actor(batch)
    before = [p.clone() for p in rnd.predictor.parameters()]
    metrics = learner.update(batch)
    assert {"charts/intrinsic_reward", "rnd_loss", "intrinsic_value_loss"} <= set(metrics)
    assert any(not torch.equal(a, b) for a, b in zip(before, rnd.predictor.parameters()))
    restored = RND(OBS_DIM, norm, algo.terms.rnd, algo.loss)
    restored.load_state_dict(rnd.state_dict())
    assert torch.equal(restored.novelty(obs), rnd.novelty(obs))
    assert torch.equal(restored.obs_rms.mean, rnd.obs_rms.mean) and restored.reward_rms.count > 1
    assert restored.running_return.shape == (ENVS,)
    assert torch.equal(restored.running_return, rnd.running_return)


def test_a_run_with_rnd_logs_it_checkpoints_its_networks_and_resumes(tmp_path) -> None:
    run = tmp_path / "run"
    args = [*SMOKE_IN_PROCESS, "algo.terms.rnd.coeff=0.5", f"paths.output_dir={run}"]
    trainer = Trainer(prepare_run(compose_train(args))[0])
    seen = logged_scalars(trainer)
    trainer.run()
    assert len(seen["charts/intrinsic_reward"]) == 2 and len(seen["losses/rnd_loss"]) == 2
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert torch.equal(state["ppo"]["rnd"]["obs_rms.mean"], trainer.algo.terms["rnd"].obs_rms.mean)
    cfg, resumed = prepare_run(
        compose_train([*args, f"resume={run}", "total_frames=384"]), {"resume", "total_frames"}
    )
    again = Trainer(cfg, resumed=resumed)
    predictor = {k: v for k, v in state["ppo"]["rnd"].items() if k.startswith("predictor.")}
    assert all(torch.equal(again.algo.terms["rnd"].state_dict()[k], v) for k, v in predictor.items())
    assert (
        float(again.algo.terms["rnd"].reward_rms.count) == float(state["ppo"]["rnd"]["reward_rms.count"]) > 1
    )
    again.run()
    assert again.updates == 3
