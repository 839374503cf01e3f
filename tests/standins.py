"""Stand-in envs for the tests, named by ``env._target_`` like the real one (``tests.standins.X``).

Spawned collector workers import them too: ``tests`` is a package, so pytest puts the repository root
on ``sys.path`` and the workers inherit it.
"""

from __future__ import annotations

import multiprocessing
from typing import Any

import gymnasium as gym
import torch

from rlgrasp.envs import PandaGraspEnv


class EnvCrash(RuntimeError):
    """The error a deliberately crashing stand-in raises."""


def pendulum(max_episode_steps: int = 50) -> Any:
    """Gymnasium's Pendulum-v1 with the grasp env's episode length: the pipeline without PyBullet."""
    return gym.make("Pendulum-v1", max_episode_steps=max_episode_steps)


class DictObservation(gym.ObservationWrapper):
    """An env whose observation is a Dict of one ``state`` entry: a Dict without a goal env's
    ``achieved_goal`` and ``desired_goal``, which HER must refuse (tests/test_gym_env.py)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.observation_space = gym.spaces.Dict({"state": env.observation_space})

    def observation(self, observation: Any) -> dict[str, Any]:
        return {"state": observation}


def pendulum_dict(max_episode_steps: int = 50) -> Any:
    """Pendulum-v1 observing ``{"state": ...}`` (``DictObservation``), registered below."""
    return DictObservation(pendulum(max_episode_steps))


#: ``env=gym env.id=tests.standins:rlgrasp_tests/PendulumDict-v0`` (importing this module registers it).
PENDULUM_DICT = "rlgrasp_tests/PendulumDict-v0"
gym.register(PENDULUM_DICT, entry_point="tests.standins:pendulum_dict")


def crashing_grasp_env(crash_after: int = 100, **env_kwargs: Any) -> Any:
    """``PandaGraspEnv(**env_kwargs)`` whose ``step`` raises ``EnvCrash`` after ``crash_after`` steps."""
    env = PandaGraspEnv(**env_kwargs)
    step, calls = env.step, [0]

    def crashing_step(*args, **kwargs):
        calls[0] += 1
        if calls[0] > crash_after:
            raise EnvCrash(f"deliberate crash after {crash_after} steps")
        return step(*args, **kwargs)

    env.step = crashing_step
    return env


def unseeded_worker_grasp_env(**env_kwargs: Any) -> Any:
    """``PandaGraspEnv(**env_kwargs)``; built in a collector worker, it first reseeds the worker's torch
    RNG from the OS, so the policy's actions there differ run to run: a worker that lost its seed."""
    if multiprocessing.parent_process() is not None:  # a spawned worker, not the learner
        torch.seed()
    return PandaGraspEnv(**env_kwargs)
