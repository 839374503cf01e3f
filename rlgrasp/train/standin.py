"""Stand-in env factories: develop and test the pipeline without PyBullet, and make it crash.

Point ``env.factory`` at one of these (``rlgrasp.train.standin:make_pendulum_env``).
"""

from __future__ import annotations

from typing import Any

from torchrl.envs import EnvBase, GymEnv


def make_pendulum_env(max_episode_steps: int = 50, **_ignored: Any) -> EnvBase:
    """Pendulum-v1 with the grasp env's episode length; the grasp-only keywords are ignored."""
    return GymEnv("Pendulum-v1", max_episode_steps=max_episode_steps)


def make_pendulum_gym(max_episode_steps: int = 50, **_ignored: Any) -> Any:
    """The gymnasium Pendulum-v1 (for ``collector.vector=gym_sync``)."""
    import gymnasium as gym

    return gym.make("Pendulum-v1", max_episode_steps=max_episode_steps)


class EnvCrash(RuntimeError):
    """The error a deliberately crashing stand-in raises."""


def make_crashing_env(
    crash_after: int = 100, factory: str = "rlgrasp.train.standin:make_pendulum_env", **kwargs: Any
) -> EnvBase:
    """Wrap another factory's env so that it raises after ``crash_after`` steps (fault tests)."""
    from rlgrasp.train.collect import resolve_factory

    kwargs.pop("gym_factory", None)
    env = resolve_factory(factory)(**kwargs)
    step = env._step
    count = {"n": 0}

    def crashing_step(tensordict):
        count["n"] += 1
        if count["n"] > crash_after:
            raise EnvCrash(f"deliberate crash after {crash_after} steps")
        return step(tensordict)

    env._step = crashing_step
    return env


def make_crashing_gym(
    crash_after: int = 100,
    gym_factory: str = "rlgrasp.train.standin:make_pendulum_gym",
    **kwargs: Any,
) -> Any:
    """The gymnasium counterpart of ``make_crashing_env`` (``env.gym_factory``)."""
    from rlgrasp.train.collect import resolve_factory

    kwargs.pop("factory", None)
    env = resolve_factory(gym_factory)(**kwargs)
    step = env.step
    count = {"n": 0}

    def crashing_step(action):
        count["n"] += 1
        if count["n"] > crash_after:
            raise EnvCrash(f"deliberate crash after {crash_after} steps")
        return step(action)

    env.step = crashing_step
    return env


def make_grasp_env_numpy_info(**kwargs: Any) -> EnvBase:
    """The grasp env with its info values as numpy scalars.

    Works around ``default_info_dict_reader`` failing on plain Python bools in TorchRL 0.14.1
    (``'bool' object has no attribute 'dtype'``) until ``rlgrasp.envs.make_torchrl_env`` does this.
    """
    import gymnasium as gym
    import numpy as np
    import torch
    from torchrl.data import Composite, Unbounded
    from torchrl.envs import GymWrapper, default_info_dict_reader

    from rlgrasp.envs import PandaGraspEnv

    class NumpyInfo(gym.Wrapper):
        def _fix(self, info):
            return {k: np.asarray(v) if isinstance(v, (bool, int, float)) else v for k, v in info.items()}

        def reset(self, **kw):
            obs, info = self.env.reset(**kw)
            return obs, self._fix(info)

        def step(self, action):
            obs, r, term, trunc, info = self.env.step(action)
            return obs, r, term, trunc, self._fix(info)

    env = GymWrapper(NumpyInfo(PandaGraspEnv(**kwargs)))
    spec = Composite(
        is_success=Unbounded((), dtype=torch.bool),
        grasped=Unbounded((), dtype=torch.bool),
        lift_height=Unbounded((), dtype=torch.float32),
    )
    return env.set_info_dict_reader(
        default_info_dict_reader(["is_success", "grasped", "lift_height"], spec=spec)
    )
