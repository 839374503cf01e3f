"""The one flat vector every scripted expert reads, from any observation a grasp env gives.

A state env gives the flat vector; a goal task's ``Dict`` gives ``observation`` (the vector without
its last three entries) and ``desired_goal`` (those three), so joined they are the flat vector and the
env's ``obs_slices`` hold for it; a camera env gives ``privileged``, the flat vector itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def flat_observation(obs: Any) -> np.ndarray:
    """The flat state vector of ``obs`` (a vector, a goal task's Dict or a camera env's Dict)."""
    if isinstance(obs, Mapping):
        if "privileged" in obs:
            return np.asarray(obs["privileged"])
        if "observation" in obs and "desired_goal" in obs:
            return np.concatenate([np.asarray(obs["observation"]), np.asarray(obs["desired_goal"])])
        raise ValueError(
            f"a scripted expert reads a flat vector, a goal Dict (observation, desired_goal) or a camera "
            f"env's privileged entry; got a mapping of {', '.join(map(str, obs))}"
        )
    return np.asarray(obs)
