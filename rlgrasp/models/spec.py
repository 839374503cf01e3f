"""The shape of an env's observation and action, read from one throw-away env: what a policy is built
for (a state policy's, ``env_spec``; a camera policy's, ``vision_spec``) and checked against."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from rlgrasp.config import ConfigError
from rlgrasp.envs.factory import EnvFactory
from rlgrasp.models.cnn import IMAGE_KEYS

#: The entry holding the full state no robot senses: what a teacher or an asymmetric critic reads.
PRIVILEGED_KEY = "privileged"


def env_spec(make_env: EnvFactory) -> dict[str, Any]:
    """Observation/action sizes and bounds and the reward's term names, from one throw-away env.
    A goal task's Dict observation is refused in one line: these learners read one vector."""
    env = make_env()
    try:
        space = env.action_space
        if isinstance(env.observation_space, gym.spaces.Dict):
            keys = ", ".join(env.observation_space.spaces)
            key = getattr(env.unwrapped, "observation_key", "env.task.observation")  # env=gym: its own
            raise ConfigError(
                f"{key}=dict: the env observes a Dict ({keys}) and this learner reads one "
                f"vector; set {key}=flat (the goal appended to the state)"
            )
        spec = {
            "obs_key": "observation",
            "obs_dim": int(env.observation_space.shape[-1]),
            "action_dim": int(space.shape[0]),
            "action_low": [float(x) for x in space.low.flatten()],
            "action_high": [float(x) for x in space.high.flatten()],
            "reward_terms": reward_term_names(env),
        }
    finally:
        env.close()
    return spec


def reward_term_names(env: Any) -> list[str]:
    """The names of the env's reward terms (none for an env without a task part: a user's own env)."""
    reward = getattr(getattr(env.unwrapped, "task", None), "reward", None)
    return list(getattr(reward, "names", ()))


def vision_spec(make_env: EnvFactory) -> dict[str, Any]:
    """Sizes of a camera env's observation parts and action, from one throw-away env."""
    env = make_env()
    try:
        space = env.observation_space
        if not isinstance(space, gym.spaces.Dict) or not any(k in space.spaces for k in IMAGE_KEYS):
            raise ConfigError("env.camera=null: a camera policy needs a camera (e.g. cameras=wrist_depth)")
        spec = {
            "obs_key": "observation",
            "obs_dim": int(space["state"].shape[-1]),
            "privileged_dim": int(space["privileged"].shape[-1]),
            # where each named part lies in `privileged` (for the student's auxiliary targets)
            "privileged_parts": {n: [s.start, s.stop] for n, s in env.unwrapped.obs_slices.items()},
            "images": {k: list(space[k].shape) for k in IMAGE_KEYS if k in space.spaces},
            "far": float(env.unwrapped.camera.spec.far),
            "action_dim": int(env.action_space.shape[0]),
            "action_low": [float(x) for x in env.action_space.low],
            "action_high": [float(x) for x in env.action_space.high],
        }
    finally:
        env.close()
    return spec
