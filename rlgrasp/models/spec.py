"""The shape of a camera env's observation and action, for building and checking camera policies."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from rlgrasp.config import ConfigError
from rlgrasp.envs.factory import EnvFactory
from rlgrasp.models.cnn import IMAGE_KEYS

#: The entry holding the full state no robot senses: what a teacher or an asymmetric critic reads.
PRIVILEGED_KEY = "privileged"


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
