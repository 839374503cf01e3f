"""collector.stagger_starts: the envs of a worker leave phase, and the cut episodes stay off the curves."""

from __future__ import annotations

import functools

import torch

from rlgrasp.envs import PandaGraspEnv
from rlgrasp.train.collection.collect import make_batched_env
from rlgrasp.train.tracking.metrics import finished_episodes

EPISODE = 10


def _rollout(stagger: bool, steps: int):
    make_env = functools.partial(PandaGraspEnv, sim={"max_episode_steps": EPISODE})
    env = make_batched_env(make_env, 4, base_seed=0, stagger=stagger)
    torch.manual_seed(0)
    try:
        return env.rollout(steps, break_when_any_done=False)  # partial resets: TorchRL resets each env
    finally:
        env.close()


def test_first_episodes_end_at_staggered_lengths_then_run_full_length():
    rollout = _rollout(stagger=True, steps=2 * EPISODE + 3)
    done = rollout["next", "done"].squeeze(-1)
    first_end = done.int().argmax(dim=1) + 1
    assert first_end.tolist() == [2, 5, 8, 10]  # round(10 * (i + 1) / 4)
    for env in range(4):
        ends = (done[env].nonzero().flatten() + 1).tolist()
        assert ends[0] == first_end[env] and ends[1] - ends[0] == EPISODE  # then full length


def test_without_stagger_the_envs_stay_in_phase():
    rollout = _rollout(stagger=False, steps=EPISODE + 2)
    done = rollout["next", "done"].squeeze(-1)
    assert done[:, EPISODE - 1].all() and done.sum() == 4


def test_cut_episodes_are_left_out_of_the_training_curves():
    rollout = _rollout(stagger=True, steps=2 * EPISODE + 3).reshape(-1)
    everything = finished_episodes(rollout)
    full = finished_episodes(rollout, full_length=EPISODE)
    # 23 steps: episodes end at 2, 12, 22 | 5, 15 | 8, 18 | 10, 20; the first three envs' first is cut
    assert everything["charts/episodes"] == 9
    assert full["charts/episodes"] == 6 and full["charts/episodic_length"] == EPISODE
