"""The policies evaluation runs, behind one interface: a checkpoint's actor, the scripted expert, or
uniform random actions; and ``PolicySource``, all a worker process needs to rebuild one and its env.

A camera env's observation is a dict (``state``, ``depth``/``rgb``, ``privileged``;
``rlgrasp.envs.GraspEnv``). A camera policy reads ``state`` (as the tensordict entry ``observation``,
the name TorchRL's gym wrapper gives it) and its images; a state policy evaluated as a camera
policy's teacher, and the scripted expert, read ``privileged``, the flat vector they know.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.envs import expert_for
from rlgrasp.envs.factory import env_factory
from rlgrasp.models.cnn import IMAGE_KEYS
from rlgrasp.policy_file import policy_from_checkpoint

POLICIES = ("checkpoint", "scripted", "random")


@dataclass
class PolicySource:
    """What the workers need to rebuild the policy and the env, all picklable.

    ``env_cfg`` is the env's ``_target_`` node as a plain dict (``rlgrasp.envs.factory.env_factory`` builds
    it). ``ckpt`` is trimmed to the entries the policy needs (weights, model config, spec), so that
    each spawned worker receives a few hundred kB rather than the optimizer state.
    """

    kind: str
    env_cfg: dict[str, Any]
    ckpt: dict[str, Any] | None = None
    ckpt_path: str | None = None
    run_dir: str | None = None
    info: dict[str, Any] = field(default_factory=dict)
    #: The checkpoint reads the camera env's ``privileged`` entry (a teacher), not ``state``.
    privileged: bool = False

    def make_env(self) -> Any:
        return env_factory(self.env_cfg)()


class Actor:
    """``reset(seed)`` before an episode, ``__call__(obs) -> action``: one interface for all policies."""

    def reset(self, seed: int) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def __call__(self, obs: Any) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


def policy_input(obs: Any, images: Sequence[str] = (), privileged: bool = False) -> TensorDict:
    """One env observation as the policy's tensordict, batch of one: ``observation`` (the flat
    vector, a camera env's ``state``, or its ``privileged`` entry) and the image entries named."""
    if isinstance(obs, Mapping):
        state = obs["privileged" if privileged else "state"]
        entries = {k: torch.as_tensor(obs[k]).unsqueeze(0) for k in images}  # RGB stays uint8
    else:
        state, entries = obs, {}
    state = torch.as_tensor(state, dtype=torch.float32).unsqueeze(0)
    return TensorDict({"observation": state, **entries}, batch_size=[1])


class CheckpointActor(Actor):
    """The trained policy (normalizer inside), fed one observation at a time."""

    def __init__(self, ckpt: dict[str, Any], deterministic: bool, privileged: bool = False) -> None:
        self.policy = policy_from_checkpoint(ckpt, "cpu")
        self.images = [k for k in IMAGE_KEYS if k in ckpt["spec"].get("images", {})]
        self.privileged = privileged
        self.mode = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM

    def reset(self, seed: int) -> None:
        # Stochastic actions: the episode's own torch RNG stream, whatever ran before it.
        torch.manual_seed(seed)

    def __call__(self, obs: Any) -> np.ndarray:
        td = policy_input(obs, self.images, self.privileged)
        with torch.no_grad(), set_exploration_type(self.mode):
            return self.policy(td)["action"][0].numpy()


class ScriptedActor(Actor):
    """The scripted expert of the env's task (deterministic); it reads the flat vector, a goal task's
    Dict or a camera env's ``privileged`` entry (the object's pose)."""

    def __init__(self, env: Any) -> None:
        self.expert = expert_for(env)

    def reset(self, seed: int) -> None:
        self.expert.reset()

    def __call__(self, obs: Any) -> np.ndarray:
        return np.asarray(self.expert(obs), dtype=np.float32)


class RandomActor(Actor):
    """Uniform actions in the action box, from an RNG seeded per episode."""

    def __init__(self, env: Any) -> None:
        self.low, self.high = env.action_space.low, env.action_space.high
        self.rng = np.random.default_rng(0)

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng([seed, 0x5EED])

    def __call__(self, obs: Any) -> np.ndarray:
        return self.rng.uniform(self.low, self.high).astype(np.float32)


def build_policy(source: PolicySource, env: Any, deterministic: bool) -> Actor:
    """The actor for ``source.kind`` (``checkpoint``, ``scripted`` or ``random``)."""
    if source.kind == "checkpoint":
        return CheckpointActor(source.ckpt, deterministic, source.privileged)
    if source.kind == "scripted":
        return ScriptedActor(env)
    if source.kind == "random":
        return RandomActor(env)
    raise ValueError(f"unknown policy kind {source.kind!r}")
