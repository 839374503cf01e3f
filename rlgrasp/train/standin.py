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
    env._step = _crash_after(env._step, crash_after)
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
    env.step = _crash_after(env.step, crash_after)
    return env


def _crash_after(step, crash_after: int):
    """``step`` that raises ``EnvCrash`` from its ``crash_after + 1``-th call on."""
    calls = 0

    def crashing_step(*args, **kwargs):
        nonlocal calls
        calls += 1
        if calls > crash_after:
            raise EnvCrash(f"deliberate crash after {crash_after} steps")
        return step(*args, **kwargs)

    return crashing_step
