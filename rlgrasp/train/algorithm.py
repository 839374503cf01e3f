"""What the training core needs from a learner: the seam between the run loop and an algorithm.

The core (``rlgrasp.train.loop``) owns everything a run has whatever learns in it: the budget, the
collector and its batches, the periodic and final evaluations, checkpoints and resume, stop signals,
faults, logging, ADR and a sweep's callback. An ``Algorithm`` owns the rest: its networks beyond the
actor, its optimizers, what it keeps between batches (a replay buffer, a dataset), and what it does
with a batch. The core builds it from ``algo._target_`` (PPO, SAC, DAgger), so adding one is
adding a package (``rlgrasp.algos.registry``) and a config file, not a branch in the loop.

The policy that acts in evaluation, is saved as the checkpoint's ``actor`` and is exported is
``actor``; the workers run a copy of ``behaviour`` (the actor itself, or DAgger's mixture of its
student and teacher), refreshed between batches (``rlgrasp.train.collection.batches``).
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

import torch
from hydra.utils import get_class

from rlgrasp.algos.registry import AlgorithmEntry, Check, entry, unknown_name

if TYPE_CHECKING:
    from rlgrasp.train.parts import Parts


class NonFiniteError(RuntimeError):
    """A NaN or inf appeared in a loss, the gradients or the parameters."""


class Algorithm:
    """A learner on the training core. Subclasses set ``actor`` (and ``behaviour`` when the workers
    run something else), implement ``update`` and extend ``state_dict``/``load_state_dict`` with
    whatever they must resume exactly."""

    #: Its value for ``config["algo"]["name"]``: a checkpoint of one algorithm is not resumed as another,
    #: and the checkpoint's key of its ``state_dict``. Its package registers it by this name.
    name = "algorithm"

    @classmethod
    def schema(cls) -> type:
        """Its config schema (a dataclass): the one its package registers (``rlgrasp.algos.registry``)."""
        return _registered(cls.name).schema_class()

    @classmethod
    def check(cls, cfg: Any, batch: int, camera: Any) -> list[Check]:
        """The problems of ``cfg.algo`` as ``(key, value, ok, allowed)``, before any worker starts."""
        return _registered(cls.name).check(cfg, batch, camera)

    def __init__(self, cfg: Any, parts: Parts, device: torch.device) -> None:
        """``cfg``: the whole training config (``cfg.algo`` is this algorithm's node); ``parts`` as
        ``rlgrasp.train.parts.build_parts`` made them (the env factory, its spec, the actor)."""
        self.cfg, self.parts, self.device = cfg, parts, device
        self.actor: torch.nn.Module = parts.actor
        #: How many updates were made (the core counts batches; an algorithm may take several steps).
        self.updates = 0

    #: Whether the run starts workers: False for one that learns from no env frames (PPO's bc_only).
    collects = True

    @property
    def behaviour(self) -> torch.nn.Module:
        """The policy the workers run (a copy of it; the core refreshes the copy between batches)."""
        return self.actor

    @property
    def learner_threads(self) -> int:
        """Torch threads for the learner's process: ``algo.learner_threads`` where the algorithm has the
        key (null: every core, for learners whose updates bound the run), else the collector's
        ``torch_threads``."""
        if "learner_threads" not in self.cfg.algo:
            return int(self.cfg.collector.torch_threads)
        return self.cfg.algo.learner_threads or os.cpu_count() or 1

    def start(self, log_scalars: Any) -> None:
        """Called once before the first batch of a fresh run (pre-training, e.g. behaviour cloning);
        ``log_scalars(metrics, frames)`` logs what it measured."""

    def update(self, batch: Any, frames: int) -> dict[str, float]:
        """Learn from a ``[envs, time]`` batch the core just counted; ``frames``: the run's frames,
        this batch's included. Returns the metrics to log (a key without a ``/`` goes under
        ``losses/``)."""
        raise NotImplementedError

    def trained_parameters(self) -> list[torch.nn.Parameter]:
        """What the core checks for non-finite values after each update."""
        return list(self.actor.parameters())

    def eval_extras(self, result: dict[str, float], evaluate: Any, episodes: int) -> dict[str, float]:
        """Extra figures logged beside ``result``, an evaluation of ``actor`` on ``episodes`` seeded
        episodes (``evaluate(policy, episodes)`` plays another policy on the same ones): a teacher's."""
        return {}

    def state_dict(self) -> dict[str, Any]:
        """Saved in the checkpoint under ``name``, beside the core's entries (``actor``, counters, config)."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what ``state_dict`` saved (``rlgrasp.legacy.algorithm_state`` finds it in a
        checkpoint of any age)."""

    def save_extra(self, run_dir: Any) -> None:
        """Write what does not belong in a checkpoint file (a replay buffer) into the run directory."""

    def check_finite(self) -> None:
        """``NonFiniteError`` if a trained parameter holds a NaN or inf (the core calls it after each
        update: a run stops before a broken network reaches a checkpoint)."""
        for p in self.trained_parameters():
            if not torch.isfinite(p).all():
                raise NonFiniteError("non-finite values in the network parameters")


def _registered(name: str) -> AlgorithmEntry:
    found = entry(name)
    if found is None:
        raise TypeError(f"algo.name={name!r}: {unknown_name(name)[3]}")
    return found


def finite_or_raise(value: torch.Tensor, what: str) -> None:
    """``NonFiniteError`` naming ``what`` when a scalar loss or norm is NaN or inf."""
    if not math.isfinite(float(value)):
        raise NonFiniteError(f"non-finite {what} {float(value)}")


def algorithm_class(algo_cfg: Any) -> type[Algorithm]:
    """The class ``algo._target_`` names (an ``Algorithm``); a config without a target (written before
    it existed) names its algorithm by ``algo.name``, read in the registry (``rlgrasp.algos``)."""
    target = algo_cfg.get("_target_") or _registered(algo_cfg.get("name")).target
    cls = get_class(target)
    if not (isinstance(cls, type) and issubclass(cls, Algorithm)):
        raise TypeError(f"algo._target_={target!r} is not an rlgrasp Algorithm")
    return cls
