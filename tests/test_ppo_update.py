"""The PPO update on a synthetic batch: advantages computed as configured, and the update learns."""

from __future__ import annotations

import math

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.algos.ppo.learner import LOG_RATIO_BOUND, PPOLearner
from rlgrasp.models.mlp import LOC_BOUND, MLPConfig, build_models
from tests.helpers import ppo_algo

OBS_DIM, ACT_DIM, ENVS, STEPS = 5, 2, 4, 32


def _batch(actor) -> TensorDict:
    """A rollout in the collector's layout, where reward is high for actions near +0.5."""
    torch.manual_seed(0)
    obs = torch.randn(ENVS, STEPS, OBS_DIM)
    td = TensorDict({"observation": obs}, [ENVS, STEPS])
    with torch.no_grad():
        actor(td)
    reward = -(td["action"] - 0.5).pow(2).sum(-1, keepdim=True)
    done = torch.zeros(ENVS, STEPS, 1, dtype=torch.bool)
    done[:, -1] = True
    td["next"] = TensorDict(
        {
            "observation": torch.randn(ENVS, STEPS, OBS_DIM),
            "reward": reward,
            "done": done,
            "terminated": torch.zeros_like(done),
            "truncated": done.clone(),
        },
        [ENVS, STEPS],
    )
    return td


def _learner(
    stale_batches: bool = False, distribution: str = "tanh_normal", **algo
) -> tuple[PPOLearner, object]:
    torch.manual_seed(0)
    model_cfg = OmegaConf.structured(MLPConfig(hidden_sizes=[16, 16], distribution=distribution))
    algo_cfg = ppo_algo(minibatch_size=32, target_kl=None, **algo)
    actor, critic, norm = build_models(OBS_DIM, -torch.ones(ACT_DIM), torch.ones(ACT_DIM), model_cfg)
    learner = PPOLearner(actor, critic, norm, algo_cfg, torch.device("cpu"), stale_batches)
    return learner, actor


@pytest.mark.parametrize("stale", [False, True])
def test_a_stale_batch_is_judged_against_the_learners_policy(stale: bool) -> None:
    """A batch collected with older weights: with ``stale_batches`` the first minibatch's KL is the
    learner's own (zero), without it the KL to the collecting policy."""
    learner, actor = _learner(stale, epochs=1)
    batch = _batch(actor)
    with torch.no_grad():  # the learner moved on since the batch was collected
        for p in actor.parameters():
            p.add_(0.3 * torch.randn_like(p))
    losses = learner.loss(_with_advantage(learner, batch, stale))
    kl = abs(float(losses["kl_approx"]))
    assert (kl < 1e-5) if stale else (kl > 1e-2)


def _with_advantage(learner: PPOLearner, batch: TensorDict, stale: bool) -> TensorDict:
    if stale:
        learner.refresh_log_probs(batch)
    with torch.no_grad():
        learner.gae(batch)
    return batch.reshape(-1)


@pytest.mark.parametrize("every_epoch, expected_calls", [(True, 3), (False, 1)])
def test_gae_runs_once_or_every_epoch(every_epoch: bool, expected_calls: int, monkeypatch) -> None:
    learner, actor = _learner(epochs=3, gae_every_epoch=every_epoch)
    calls = []
    original = learner.gae.forward
    monkeypatch.setattr(learner.gae, "forward", lambda td, **kw: calls.append(1) or original(td, **kw))
    metrics = learner.update(_batch(actor))
    assert len(calls) == expected_calls
    assert metrics["epochs"] == 3.0


@pytest.mark.parametrize(
    "every_epoch, distribution", [(True, "tanh_normal"), (False, "tanh_normal"), (False, "normal")]
)
def test_update_moves_the_policy_towards_higher_reward(every_epoch: bool, distribution: str) -> None:
    learner, actor = _learner(distribution=distribution, epochs=10, lr=1e-2, gae_every_epoch=every_epoch)
    batch = _batch(actor)
    probe = TensorDict({"observation": batch["observation"].reshape(-1, OBS_DIM)}, [ENVS * STEPS])
    loc_before = actor(probe.clone())["loc"].mean(0)
    for _ in range(5):
        learner.update(_batch(actor))
    loc_after = actor(probe.clone())["loc"].mean(0)
    assert ((loc_after - 0.5).abs() < (loc_before - 0.5).abs()).all(), (loc_before, loc_after)


def test_a_gaussian_policy_keeps_the_unclipped_sample_and_its_own_log_prob() -> None:
    """``model.distribution=normal`` (SB3's policy): actions may leave the bounds (the env clips them),
    and the log-prob is the plain Gaussian's of the sample as drawn."""
    _, actor = _learner(distribution="normal")
    with torch.no_grad():
        # a std of e: many samples beyond +-1
        actor.module[0].module.scale.state_independent_scale.fill_(1.0)
        td = actor(TensorDict({"observation": torch.randn(512, OBS_DIM)}, [512]))
    assert (td["action"].abs() > 1).any()
    gaussian = torch.distributions.Normal(td["loc"], td["scale"])
    expected = gaussian.log_prob(td["action"]).sum(-1)
    torch.testing.assert_close(td["action_log_prob"], expected)


def test_the_adaptive_rate_follows_the_kl(monkeypatch) -> None:
    """``algo.schedule.desired_kl``: the rate grows by 1.5 after a minibatch whose KL is below half
    the target, shrinks by 1.5 above twice the target, stays in [1e-5, 1e-2], and is what ``lr_at`` reports
    whatever the frames (the linear annealing is off)."""
    learner, actor = _learner(epochs=1, lr=1e-3, desired_kl=0.01)  # 128 frames: 4 minibatches
    kls = iter([0.001, 0.05, 0.01, 0.001])
    monkeypatch.setattr(learner, "_minibatch_step", lambda minibatch, sums: next(kls))
    metrics = learner.update(_batch(actor))
    assert learner.optimizer.param_groups[0]["lr"] == pytest.approx(1e-3 * 1.5 / 1.5 * 1.5)
    # Logged: the rate the four minibatches stepped at, on average (1, 1.5, 1 and 1 x 1e-3).
    assert metrics["charts/learning_rate"] == pytest.approx(1.125e-3)
    assert learner.lr_at(frames=10**6, total_frames=10**6) == pytest.approx(1.5e-3)
    learner.set_lr(9e-3)
    learner.adapt_lr(0.0)
    assert learner.optimizer.param_groups[0]["lr"] == 1e-2
    learner.actor_frozen = True  # the critic's warm-up: the actor is still, its KL says nothing
    kls = iter([0.0] * 4)
    learner.update(_batch(actor))
    assert learner.optimizer.param_groups[0]["lr"] == 1e-2


def test_without_a_desired_kl_the_rate_anneals() -> None:
    learner, _ = _learner(lr=1e-3)
    assert learner.lr_at(frames=500, total_frames=1000) == pytest.approx(5e-4)


def test_the_adaptive_rate_resumes_with_adams_state() -> None:
    """A resumed run continues from the rate the KL left: it travels in the optimizer's state dict."""
    learner, _ = _learner(desired_kl=0.01)
    learner.set_lr(2.5e-4)
    resumed, _ = _learner(desired_kl=0.01)
    resumed.optimizer.load_state_dict(learner.optimizer.state_dict())
    assert resumed.lr_at(frames=0, total_frames=1000) == pytest.approx(2.5e-4)


def _at_the_std_floor(
    distribution: str = "tanh_normal", stale_batches: bool = False
) -> tuple[PPOLearner, object]:
    """A learner whose actor's standard deviation sits at its floor (``model.min_std``)."""
    torch.manual_seed(0)
    model_cfg = OmegaConf.structured(
        MLPConfig(hidden_sizes=[16, 16], init_log_std=-10.0, distribution=distribution)
    )
    algo_cfg = ppo_algo(minibatch_size=32, target_kl=None)
    actor, critic, norm = build_models(OBS_DIM, -torch.ones(ACT_DIM), torch.ones(ACT_DIM), model_cfg)
    return PPOLearner(actor, critic, norm, algo_cfg, torch.device("cpu"), stale_batches), actor


def _set_loc(actor, value: float) -> None:
    """Every observation's pre-tanh mean ``value`` (the actor's last layer: zero weights, that bias)."""
    last = [m for m in actor.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.fill_(value)


@pytest.mark.parametrize("distribution", ["tanh_normal", "normal"])
def test_the_pre_tanh_mean_is_bounded_for_a_tanh_actor_only(distribution: str) -> None:
    _, actor = _at_the_std_floor(distribution)
    _set_loc(actor, 1e3)
    td = actor(TensorDict({"observation": torch.randn(8, OBS_DIM)}, [8]))
    expected = LOC_BOUND if distribution == "tanh_normal" else 1e3  # a Gaussian's action is clipped
    assert torch.equal(td["loc"], torch.full_like(td["loc"], expected))


def test_a_saturated_action_at_the_std_floor_keeps_the_ratio_and_loss_finite() -> None:
    """PPO from pixels stopped on a non-finite loss: actions collected with the mean far beyond
    saturation and the standard deviation at its floor have log-probs thousands below the
    learner's once its mean moves back, and exp of the difference is inf."""
    learner, actor = _at_the_std_floor(stale_batches=True)  # collector.overlap's path
    _set_loc(actor, 30.0)  # the collecting policy: saturated
    n = 64
    td = TensorDict({"observation": torch.randn(n, OBS_DIM)}, [n])
    with torch.no_grad():
        actor(td)
    learner.refresh_log_probs(td)  # of the saturated actions, from their pre-image atanh(action)
    _set_loc(actor, 7.0)  # the learner's, a few updates on: near that pre-image
    td["advantage"] = torch.randn(n, 1)
    td["value_target"] = torch.zeros(n, 1)
    losses = learner.loss(td)
    assert float(losses["max_ratio"]) <= math.exp(LOG_RATIO_BOUND) * 1.001  # inf before the cap
    total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
    assert torch.isfinite(total), {k: float(v) for k, v in losses.items() if v.numel() == 1}
    total.backward()
    assert all(torch.isfinite(p.grad).all() for p in actor.parameters() if p.grad is not None)
