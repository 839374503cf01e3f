"""rlgrasp: parallel RL training of robot grasp-and-lift tasks in PyBullet."""

import importlib.util
import sys

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

    sim = dict(kwargs.pop("sim", None) or {})
    sim.setdefault("max_episode_steps", 2**31 - 1)
    return GraspEnv(sim=sim, **kwargs)


def _skip_lookups_of_missing_pandas() -> None:
    """Mark pandas as absent when it is not installed, so that looking it up is a dictionary read.

    TensorDict 0.14 asks ``importlib.util.find_spec("pandas")`` each time a ``TensorDictModule``
    writes a tensor it computed (``TensorDict.from_any``): without pandas installed that is a search
    of every ``sys.path`` entry, about a tenth of a millisecond, paid on every actor step in every
    worker and several times in every gradient step. ``None`` in ``sys.modules`` is Python's own
    mark for a module that cannot be imported: ``import pandas`` still fails as it would have, and
    an installed pandas is left alone."""
    if "pandas" not in sys.modules and importlib.util.find_spec("pandas") is None:
        sys.modules["pandas"] = None  # type: ignore[assignment]


_skip_lookups_of_missing_pandas()

#: The goal tasks by gymnasium id (panda-gym's names, rlgrasp's namespace): a Dict observation of
#: ``observation``, ``achieved_goal`` and ``desired_goal`` and a vectorized ``compute_reward``.
GOAL_ENV_IDS = {
    "rlgrasp/PandaPickAndPlace-v0": "pick_place",
    "rlgrasp/PandaPush-v0": "push",
    "rlgrasp/PandaStack-v0": "stack",
}

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        ENV_ID, entry_point="rlgrasp:make_registered_env", max_episode_steps=DEFAULT_EPISODE_STEPS
    )
    for env_id, task in GOAL_ENV_IDS.items():
        gymnasium.register(
            env_id,
            entry_point="rlgrasp:make_registered_env",
            max_episode_steps=DEFAULT_EPISODE_STEPS,
            kwargs={"task": task},
        )

__version__ = "0.1.0"
