"""Stand-in env factories: develop and test the pipeline without PyBullet, and make it crash.

Point ``env.factory`` at one of these (``rlgrasp.train.standin:make_pendulum_env``).
"""

from __future__ import annotations

from typing import Any

from torchrl.envs import EnvBase, GymEnv


def make_pendulum_env(max_episode_steps: int = 50, **_ignored: Any) -> EnvBase:
    """Pendulum-v1 with the grasp env's episode length; the grasp-only keywords are ignored."""
    return GymEnv("Pendulum-v1", max_episode_steps=max_episode_steps)


class EnvCrash(RuntimeError):
    """The error a deliberately crashing stand-in raises."""


def make_crashing_env(
    crash_after: int = 100, factory: str = "rlgrasp.train.standin:make_pendulum_env", **kwargs: Any
) -> EnvBase:
    """Wrap another factory's env so that it raises after ``crash_after`` steps (fault tests)."""
    from rlgrasp.train.collect import resolve_factory

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
