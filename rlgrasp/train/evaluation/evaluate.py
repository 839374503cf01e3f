"""Periodic evaluation: deterministic actions on the same seeded episodes every time.

Runs on a small vector env (built like a collector worker's): in the learner's process, or with
``eval.background`` in a process of its own (``rlgrasp.train.evaluation.eval_process``) that runs this
same code.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, ExplorationType, set_exploration_type

from rlgrasp.envs.factory import env_factory, episode_steps
from rlgrasp.train.collection.collect import EnvFactory, make_batched_env
from rlgrasp.utils import plain


def episode_stats(td: TensorDictBase) -> dict[str, torch.Tensor]:
    """Return, length and success of each env's first finished episode in a ``[envs, time]`` rollout."""
    done = td["next", "done"].reshape(td.shape)
    finished = done.any(-1)
    first = torch.where(
        finished, done.float().argmax(-1), torch.full_like(finished, td.shape[-1] - 1, dtype=torch.long)
    )
    steps = torch.arange(td.shape[-1]).expand(td.shape)
    upto = steps <= first.unsqueeze(-1)
    reward = td["next", "reward"].reshape(td.shape)
    out = {
        "finished": finished,
        "return": (reward * upto).sum(-1),
        "length": (first + 1).float(),
    }
    if ("next", "is_success") in td.keys(True):
        success = td["next", "is_success"].reshape(td.shape)
        out["success"] = success.gather(-1, first.unsqueeze(-1)).squeeze(-1).float()
    return out


class Evaluator:
    """Evaluates ``episodes`` episodes on ``num_envs`` in-process envs seeded from ``seed``."""

    def __init__(self, make_env: EnvFactory, max_steps: int, episodes: int, num_envs: int, seed: int) -> None:
        self.make_env = make_env
        self.episodes = episodes
        self.num_envs = max(1, min(num_envs, episodes))
        self.seed = seed
        self.max_steps = int(max_steps)
        self._env: EnvBase | None = None

    @torch.no_grad()
    def run(self, policy, episodes: int | None = None) -> dict[str, float]:
        """Mean return and success over ``episodes`` (default: the constructor's); the first
        episodes are the same whatever the count, so a longer evaluation extends a shorter one."""
        episodes = episodes or self.episodes
        return summarize(self.play(policy, episodes), episodes)

    def rounds(self, episodes: int) -> int:
        """How many rounds of ``num_envs`` episodes ``episodes`` take."""
        return math.ceil(episodes / self.num_envs)

    @torch.no_grad()
    def play(
        self, policy, episodes: int, first_round: int = 0, rounds: int | None = None
    ) -> dict[str, torch.Tensor]:
        """Each episode's return (and success) of rounds ``first_round`` to ``first_round + rounds``
        of an evaluation of ``episodes`` (default: to its last round); round r plays the episodes
        seeded ``seed + r * num_envs + i``, so the rounds of one evaluation may be played in several
        processes and concatenated in order (``summarize``)."""
        if self._env is None:
            self._env = make_batched_env(
                self.make_env,
                self.num_envs,
                self.seed,
                torch_threads=torch.get_num_threads(),
                episode_stats=False,
                seed_torch=False,
            )
        last = self.rounds(episodes) if rounds is None else min(first_round + rounds, self.rounds(episodes))
        returns, successes = [], []
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            for r in range(first_round, last):
                self._env.set_seed(self.seed + r * self.num_envs)
                td = self._env.rollout(self.max_steps, policy, break_when_any_done=False)
                stats = episode_stats(td)
                returns.append(stats["return"])
                if "success" in stats:
                    successes.append(stats["success"])
        out = {"return": torch.cat(returns)}
        if successes:
            out["success"] = torch.cat(successes)
        return out

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without its envs: a copy (the background evaluation process) builds its own."""
        return {**self.__dict__, "_env": None}

    def close(self) -> None:
        if self._env is not None and not self._env.is_closed:
            self._env.close()
        self._env = None


def summarize(
    played: dict[str, torch.Tensor] | list[dict[str, torch.Tensor]], episodes: int
) -> dict[str, float]:
    """Mean return and success of the first ``episodes`` of ``Evaluator.play``'s episodes (a list:
    the parts of one evaluation in round order, concatenated)."""
    parts = played if isinstance(played, list) else [played]
    returns = torch.cat([p["return"] for p in parts])
    out = {"mean_reward": float(returns[:episodes].mean())}
    if all("success" in p for p in parts):
        out["success_rate"] = float(torch.cat([p["success"] for p in parts])[:episodes].mean())
    return out


def periodic_evaluator(make_env: EnvFactory, cfg: Any) -> Evaluator:
    """Training's periodic evaluator for a training config: its episodes, envs and seeds (apart from
    every collector worker's), so anything evaluating "as training does" gets the same episodes; on
    ``eval.randomization`` when set, else on ``make_env``'s."""
    e = cfg.eval
    if e.get("randomization") is not None:
        make_env = env_factory({**plain(cfg.env), "randomization": plain(e.randomization)})
    seed = cfg.seed * 1_000_003 + e.seed_offset
    return Evaluator(make_env, episode_steps(cfg.env), e.episodes, e.num_envs, seed)
