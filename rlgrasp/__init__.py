"""rlgrasp: parallel RL training of robot grasp-and-lift tasks in PyBullet."""

import gymnasium

ENV_ID = "rlgrasp/PandaGrasp-v0"
#: Steps per episode of ``gymnasium.make(ENV_ID)`` (``max_episode_steps=`` changes it).
DEFAULT_EPISODE_STEPS = 50


def make_registered_env(**kwargs):
    """The entry point of ``ENV_ID``: gymnasium's ``TimeLimit`` ends the episodes (at
    ``gymnasium.make``'s ``max_episode_steps``), so the env's own limit is set out of its way unless
    the keyword is given to the env itself."""
    # Lazy: `import rlgrasp` (configs, tools) must not load PyBullet and the env modules.
    from rlgrasp.envs import GraspEnv

    kwargs.setdefault("max_episode_steps", 2**31 - 1)
    return GraspEnv(**kwargs)


if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        ENV_ID, entry_point="rlgrasp:make_registered_env", max_episode_steps=DEFAULT_EPISODE_STEPS
    )

__version__ = "0.1.0"
