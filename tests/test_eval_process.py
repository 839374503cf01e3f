"""The periodic evaluation in its own process (``eval.background``): the numbers the learner's own
evaluation gives for the same weights, the weights as they were when submitted, a failure that says
what failed, and a process that always ends."""

from __future__ import annotations

import multiprocessing
import time

import pytest
import torch
from omegaconf import OmegaConf

from rlgrasp.envs.factory import env_factory
from rlgrasp.train.evaluation.eval_process import BackgroundEvaluator, EvalProcessError
from rlgrasp.train.evaluation.evaluate import periodic_evaluator, summarize
from rlgrasp.train.loop import seed_everything
from rlgrasp.train.parts import build_parts


def _eval_children() -> list[multiprocessing.Process]:
    return [p for p in multiprocessing.active_children() if p.name == "rlgrasp-eval"]


SMOKE = ("experiment=smoke",)  # 4 episodes on 4 envs
CAMERA = ("experiment=grasp_vision_ppo", "eval.episodes=2", "eval.num_envs=2")  # depth images in


@pytest.fixture
def parts(train_cfg, request):
    """An experiment's actor (normalizer fitted) and periodic evaluator (``SMOKE`` unless the test is
    parametrized indirectly with other overrides)."""
    cfg = train_cfg(*getattr(request, "param", SMOKE))
    seed_everything(0)
    parts = build_parts(cfg)
    parts.norm.update(torch.randn(64, parts.spec["obs_dim"]) * 0.3)
    parts.actor.eval()
    evaluator = periodic_evaluator(parts.make_env, cfg)
    yield parts, evaluator
    evaluator.close()


def _perturb(actor: torch.nn.Module) -> None:
    with torch.no_grad():
        for p in actor.parameters():
            p.add_(torch.randn_like(p) * 0.3)


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
@pytest.mark.parametrize(
    "parts", [SMOKE, pytest.param(CAMERA, marks=pytest.mark.slow)], indirect=True, ids=["state", "camera"]
)
def test_the_background_process_gives_the_learners_numbers_for_the_submitted_weights(parts) -> None:
    parts, evaluator = parts
    actor, episodes = parts.actor, evaluator.episodes
    background = BackgroundEvaluator(evaluator, actor)
    try:
        for frames in (1024, 2048):
            want = evaluator.run(actor, episodes)
            background.submit(frames, actor.state_dict(), episodes, keep="snapshot")
            _perturb(actor)  # training goes on: the process must evaluate the weights as submitted
            pending, got = background.wait()
            assert (pending.frames, pending.episodes, pending.keep) == (frames, episodes, "snapshot")
            assert got == want  # bit for bit, on this machine
        assert evaluator.run(actor, episodes) != want  # the perturbation changes the numbers: not vacuous
    finally:
        background.close()
    assert _eval_children() == []


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_an_evaluation_shared_with_the_process_gives_one_processs_numbers(parts) -> None:
    """The final evaluation's split: the process plays the later rounds (its result can be looked at
    before ``wait`` without waiting), the learner the first ones; joined in order they are
    ``Evaluator.run``'s figures."""
    parts, evaluator = parts
    actor, episodes = parts.actor, 7  # 2 rounds of 4 envs, the last one cut to 3 episodes
    want = evaluator.run(actor, episodes)
    background = BackgroundEvaluator(evaluator, actor)
    try:
        assert not background.running and background.ready() is None
        background.submit(2048, actor.state_dict(), episodes, part=(1, 1))
        mine = evaluator.play(actor, episodes, 0, 1)
        while background.ready() is None:
            time.sleep(0.05)
        pending, theirs = background.wait()
        assert pending.part == (1, 1) and len(mine["return"]) == len(theirs["return"]) == 4
        assert summarize([mine, theirs], episodes) == want
    finally:
        background.close()
    assert _eval_children() == []


@pytest.mark.full  # a second evaluation process
def test_a_failing_evaluation_says_why_and_the_process_ends(parts) -> None:
    parts, evaluator = parts
    crashing = {"_target_": "tests.standins.crashing_grasp_env", "crash_after": 5}
    env_cfg = OmegaConf.merge(OmegaConf.to_container(parts.cfg.env), crashing)
    evaluator.make_env = env_factory(env_cfg)
    background = BackgroundEvaluator(evaluator, parts.actor)
    try:
        background.submit(512, parts.actor.state_dict(), 4)
        with pytest.raises(EvalProcessError, match="deliberate crash after 5 steps"):
            background.wait()
    finally:
        background.close()
    assert _eval_children() == []


def test_close_ends_a_process_in_the_middle_of_an_evaluation(parts) -> None:
    parts, evaluator = parts
    background = BackgroundEvaluator(evaluator, parts.actor)
    background.submit(512, parts.actor.state_dict(), 400)  # minutes of episodes
    (child,) = _eval_children()
    background.close()
    assert not child.is_alive() and _eval_children() == []
