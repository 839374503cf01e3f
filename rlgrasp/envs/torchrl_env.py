"""The env wrapped for TorchRL, built by a top-level (picklable, spawn-safe) factory."""

from __future__ import annotations

from typing import Any

import torch
from torchrl.data import Composite, Unbounded
from torchrl.envs import GymWrapper, default_info_dict_reader

from rlgrasp.envs.panda_grasp import PandaGraspEnv

INFO_KEYS = ("is_success", "grasped", "lift_height")


def make_torchrl_env(device: str | torch.device = "cpu", **env_kwargs: Any) -> GymWrapper:
    """``GymWrapper(PandaGraspEnv(**env_kwargs))`` whose steps carry the info keys in INFO_KEYS.

    Defined at module level so that TorchRL's spawned workers can unpickle it.
    """
    env = GymWrapper(PandaGraspEnv(**env_kwargs), device=device)
    spec = Composite(
        is_success=Unbounded((), dtype=torch.bool),
        grasped=Unbounded((), dtype=torch.bool),
        lift_height=Unbounded((), dtype=torch.float32),
    )
    return env.set_info_dict_reader(default_info_dict_reader(list(INFO_KEYS), spec=spec))
