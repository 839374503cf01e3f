"""Hindsight experience replay (HER, Andrychowicz et al. 2017) in SAC's replay, on a goal task's flat
observation (``algo.her``; TQC takes it as SAC's).

A sampled minibatch's online rows are relabelled, ``relabel_ratio`` of them: the desired goal (the
observation's last three entries, in ``observation`` and ``next.observation``) becomes where the object
was after a later step of the same episode (``future``, SB3's way: that step may be the row's own) or
after the episode's last stored step (``final``), and ``next.reward`` becomes what the task's sparse rule
pays for it (``GoalTask.compute_reward``: 1 within ``distance_threshold``, else 0). ``terminated`` stays as
stored: goal tasks end on success only with ``terminate_on_success``, which then ended the episode at its
own goal. The achieved goal is read from the observation's ``object_pos``, with the env's sensor noise (a
few millimetres at most under the default randomization, against a 5 cm threshold).

Another package's goal env (``env=gym``: panda-gym's, gymnasium-robotics') is relabelled the same way on
its flat observation (``rlgrasp.envs.gym_env``: ``achieved_goal`` and ``desired_goal`` last, where its
``obs_slices`` say), and paid by its own ``compute_reward``, whatever its scale (panda-gym: -1 / 0).

Why not TorchRL's ``HERReplayBuffer`` (torchrl.data, 0.14): it takes an episode to be a run of adjacent
storage rows ended by ``done``, which holds where one env writes whole episodes. SAC writes each collector
batch flattened, ``[envs, steps]``: every env's segment in turn, so an episode's steps lie in many batches,
apart, with other envs' steps between them, and its "future" goal would come from another episode. It
also reads the goals from keys of their own, where these learners read one flat vector. Here each stored
transition keeps its episode's number (``EPISODE_KEY``: from the batch's layout and ``("next", "done")``,
and saved with the replay files, so that a resumed run relabels what it reads back), and ``Episodes``
keeps each buffer row's episode as the list of its rows in the order written.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase

from rlgrasp.envs.factory import EnvFactory
from rlgrasp.envs.gym_env import GymEnv
from rlgrasp.envs.tasks.goal import GoalTask
from rlgrasp.errors import ConfigError
from rlgrasp.models.mlp import OBS_KEY

#: Where a stored transition keeps the number of its episode (unique within the run).
EPISODE_KEY = "her_episode"


@dataclass(frozen=True)
class GoalLayout:
    """Where a goal task's flat observation holds the achieved and the desired goal, and what a goal
    pays: the distance within which it is met (rlgrasp's tasks), or the env's own ``compute_reward``
    (``env_reward``: another package's goal env, vectorized over rows)."""

    achieved: slice
    desired: slice
    distance_threshold: float = 0.0
    env_reward: Callable[[Any, Any, Any], Any] | None = None

    @property
    def size(self) -> int:
        """The entries of one achieved goal."""
        return self.achieved.stop - self.achieved.start

    def reward(self, achieved: torch.Tensor, desired: torch.Tensor) -> torch.Tensor:
        """What the goals pay, shaped as ``next.reward`` (``[n, 1]``): ``GoalTask.compute_reward`` on
        tensors, or the env's own ``compute_reward``, given one empty info a row (the replay keeps no
        infos; Stable-Baselines3's HER passes one dict a row too)."""
        if self.env_reward is None:
            distance = torch.linalg.vector_norm(achieved - desired, dim=-1, keepdim=True)
            return (distance < self.distance_threshold).to(torch.float32)
        infos = np.array([{} for _ in range(achieved.shape[0])], dtype=object)
        paid = self.env_reward(achieved.cpu().numpy(), desired.cpu().numpy(), infos)
        return torch.as_tensor(np.asarray(paid, dtype=np.float32)).reshape(-1, 1).to(achieved.device)


def goal_layout(make_env: EnvFactory) -> GoalLayout:
    """The goal slices and threshold of the env's task, from one throw-away env; a task HER cannot
    relabel is refused in one line. Relabelling recomputes ``GoalTask``'s rule (the object within
    ``distance_threshold`` of the goal), so a task whose success or reward adds to that rule is refused:
    stack's success also needs the fingers off the top cube and the base unmoved, and a goal moved to
    where the top cube happened to be has no base under it, so no relabelled reward would be the one
    its episode could have earned."""
    env = make_env()
    if isinstance(env.unwrapped, GymEnv):
        return _gym_layout(env.unwrapped)
    try:
        task = getattr(env.unwrapped, "task", None)
        name = type(task).__name__
        if not isinstance(task, GoalTask):
            raise ConfigError(
                f"algo.her.enabled=true: the task {name} has no goal to relabel; HER needs a goal task "
                "(task=pick_place or task=push)"
            )
        own = (
            type(task).succeeded is not GoalTask.succeeded
            or type(task).compute_reward is not GoalTask.compute_reward
        )
        if own:
            raise ConfigError(
                f"algo.her.enabled=true: {name}'s success is not the goal distance alone (stack: the fingers "
                "off the cube and the base unmoved too), so a relabelled goal's reward cannot be recomputed; "
                "HER takes task=pick_place or task=push"
            )
        slices = env.unwrapped.obs_slices
        return GoalLayout(slices["object_pos"], slices["desired_goal"], float(task.distance_threshold))
    finally:
        env.close()


def _gym_layout(env: GymEnv) -> GoalLayout:
    """Another package's goal env (``env=gym``): its goals' slices, and its own ``compute_reward``,
    which keeps the env open until the layout is dropped (panda-gym's is a method of the env's task).
    An env without goals is refused in one line (``rlgrasp.train.validate.validate_train`` says it first)."""
    if not env.goal_env or not env.flat:
        env.close()
        raise ConfigError(
            f"algo.her.enabled=true: env.id={env.env_id!r} observes no achieved_goal and desired_goal in "
            "one vector with a compute_reward; HER relabels a goal env's with env.observation=flat"
        )
    slices = env.obs_slices
    layout = GoalLayout(slices["achieved_goal"], slices["desired_goal"], env_reward=env.compute_reward)
    weakref.finalize(layout, env.close)
    return layout


class Episodes:
    """Which episode each replay row holds a step of, and that episode's rows in the order written.

    Rows of one episode are written in step order and the ring overwrites rows in the order written,
    so every row after a live row in its episode's list is live too: a later step is a later entry."""

    def __init__(self, size: int) -> None:
        self.rows_of: list[list[int] | None] = [None] * size  # each row's episode (a list shared by its rows)
        self.position = [0] * size  # each row's place in that list
        self.growing: dict[int, list[int]] = {}  # episodes that may still get rows, by number
        self.open: list[int] | None = None  # each env's episode in progress (None: none yet)
        self.next_number = 0

    def label(self, batch: TensorDictBase) -> torch.Tensor:
        """The episode number of each transition of a collector batch ``[..., steps]``, in the order of
        ``batch.reshape(-1)``. Each row of ``[envs, steps]`` is one env in every batch (the collectors
        stack their workers in order), continuing that env's episode of the batch before until
        ``("next", "done")``; the first batch of a run (or of a resumed one) starts new episodes."""
        steps = batch.shape[-1]
        done = batch["next", "done"].reshape(-1, steps).cpu()
        if self.open is None or len(self.open) != done.shape[0]:
            self.open = [self._new() for _ in range(done.shape[0])]
        self.growing = {n: self.growing[n] for n in self.open if n in self.growing}  # the others ended
        numbers = torch.empty(done.shape, dtype=torch.int64)
        for env, ends in enumerate(done):
            start = 0
            for end in ends.nonzero().flatten().tolist():
                numbers[env, start : end + 1] = self.open[env]
                self.open[env], start = self._new(), end + 1
            numbers[env, start:] = self.open[env]
        return numbers.reshape(-1)

    def _new(self) -> int:
        self.next_number += 1
        return self.next_number - 1

    def written(self, rows: torch.Tensor, numbers: torch.Tensor) -> None:
        """Rows ``rows`` of the buffer now hold steps of episodes ``numbers``, in the order written."""
        numbers_list = numbers.tolist()
        for row, number in zip(rows.tolist(), numbers_list):
            episode = self.growing.setdefault(number, [])
            episode.append(row)
            self.rows_of[row], self.position[row] = episode, len(episode) - 1
        if numbers_list:  # a resumed run's new episodes are numbered after those read back
            self.next_number = max(self.next_number, max(numbers_list) + 1)

    def goal_rows(self, rows: torch.Tensor, strategy: str) -> torch.Tensor:
        """For each row, a row of the same episode at the same step or later (``future``: drawn
        uniformly; ``final``: its last stored one)."""
        draws = torch.rand(rows.numel()).tolist()
        out = []
        for row, draw in zip(rows.tolist(), draws):
            episode, here = self.rows_of[row], self.position[row]
            last = len(episode) - 1
            pick = last if strategy == "final" else min(last, here + int(draw * (last - here + 1)))
            out.append(episode[pick])
        return torch.tensor(out, dtype=torch.int64)


class Hindsight:
    """``algo.her`` on SAC's online replay: the episodes of its rows, and the relabelling of a sample."""

    def __init__(self, her_cfg: Any, layout: GoalLayout, size: int, device: torch.device) -> None:
        self.strategy = str(her_cfg.strategy)
        self.ratio = float(her_cfg.relabel_ratio)
        self.layout = layout
        self.episodes = Episodes(size)
        # Each row's achieved goal after its step (3 floats a row for a position): a goal is read from
        # here, not gathered from the buffer's every key
        self.achieved = torch.zeros(size, layout.size, device=device)
        self.paid = 0.0  # the share of the last minibatch's relabelled rows whose new goal was met

    def written(self, rows: torch.Tensor, transitions: TensorDictBase) -> None:
        """Rows ``rows`` of the buffer now hold ``transitions`` (with their ``EPISODE_KEY``)."""
        self.episodes.written(rows, transitions[EPISODE_KEY].cpu())
        self.achieved[rows.to(self.achieved.device)] = transitions["next", OBS_KEY][
            :, self.layout.achieved
        ].to(self.achieved)

    def relabel(self, sample: TensorDictBase) -> tuple[TensorDictBase, torch.Tensor]:
        """``sample`` (drawn from the buffer, with its rows' ``index``) with ``relabel_ratio`` of its rows,
        drawn at random, given a goal from their episode and the reward it pays; the rows relabelled."""
        rows = sample["index"].reshape(-1).cpu()
        chosen = torch.randperm(rows.numel())[: round(rows.numel() * self.ratio)]
        if chosen.numel() == 0:
            return sample, chosen
        achieved, desired = self.layout.achieved, self.layout.desired
        goal_rows = self.episodes.goal_rows(rows[chosen], self.strategy)
        goals = self.achieved[goal_rows.to(self.achieved.device)].to(sample.device)
        index = chosen.to(sample.device)
        observation, next_observation = sample[OBS_KEY].clone(), sample["next", OBS_KEY].clone()
        reward = sample["next", "reward"].clone()
        observation[index, desired] = goals
        next_observation[index, desired] = goals
        reward[index] = self.layout.reward(next_observation[index, achieved], goals).to(reward.dtype)
        self.paid = float(reward[index].mean())
        sample = sample.clone(False)
        sample.set(OBS_KEY, observation)
        sample.set(("next", OBS_KEY), next_observation)
        sample.set(("next", "reward"), reward)
        return sample, chosen
