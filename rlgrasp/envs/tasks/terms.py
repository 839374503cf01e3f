"""Reward terms: a task's reward as named, weighted functions of the step's readings.

The way Isaac Lab's manager-based envs declare rewards: each term is a small function with a name
that shows in the logs, a weight and its own parameters, all set in config
(``env.task.reward.terms.lift: {weight: 2}``). A task ships named term sets (``dense``, ``sparse``);
a config may instead give the terms itself, and a user's own term is any callable the user's config
names with ``_target_`` (``docs/tasks.md``). ``RewardTerms`` sums the weighted terms in their declared
order, divides by the sum of the weights when ``normalize`` (a step then pays at most 1 when every
term is in [0, 1]) and keeps each term's episode sum for the logs (``info["reward_terms"]``).
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from rlgrasp.locate import NotImportable, locate

#: A term: ``term(task, readings, **params) -> float``; ``readings`` are the step's true readings
#: (robot and task parts by name, ``rlgrasp.envs.observation``), ``task`` the task that owns them.
TermFn = Callable[..., float]

#: The keys of a term's node that are not its function's parameters.
TERM_KEYS = ("weight", "_target_")


class RewardConfigError(ValueError):
    """A reward set or term that cannot be built; the message is one line naming the key."""


def reach(task: Any, readings: Mapping[str, Any], scale: float = 5.0) -> float:
    """1 - tanh(scale x the grasp point's distance to the object's centre): pulls the hand in."""
    offset = readings["object_centre"] - readings["grasp_pos"]  # its norm as np.linalg.norm computes it
    return 1.0 - math.tanh(scale * math.sqrt(offset.dot(offset)))


def grasp(task: Any, readings: Mapping[str, Any]) -> float:
    """1 while both fingers touch the object."""
    return float(readings["grasped"][0] > 0.5)


def success(task: Any, readings: Mapping[str, Any]) -> float:
    """1 while the task's success condition holds."""
    return float(task.succeeded(readings))


def resolve_terms(
    spec: Any, presets: Mapping[str, Mapping[str, Any]], library: Mapping[str, TermFn], where: str
):
    """``spec`` (a preset name of ``presets``, or a mapping ``{terms: {...}, normalize: bool}``) ->
    ``(terms, normalize)`` with each term's node; unknown names fail naming the key and what is allowed."""
    if isinstance(spec, str):
        if spec not in presets:
            raise RewardConfigError(
                f"unknown reward {spec!r} ({where}); this task's term sets: {', '.join(presets)}, or a "
                "mapping {terms: {...}, normalize: true|false}"
            )
        spec = presets[spec]
    if not isinstance(spec, Mapping) or not isinstance(spec.get("terms"), Mapping):
        raise RewardConfigError(
            f"{where} must be a term set name ({', '.join(presets)}) or a mapping with a 'terms' mapping, "
            f"got {spec!r}"
        )
    unknown = sorted(set(spec) - {"terms", "normalize"})
    if unknown:
        raise RewardConfigError(f"unknown key {unknown[0]!r} in {where}; keys: terms, normalize")
    return dict(spec["terms"]), bool(spec.get("normalize", True))


class RewardTerms:
    """The weighted terms of one reward, and their episode sums."""

    def __init__(
        self,
        spec: Any,
        presets: Mapping[str, Mapping[str, Any]],
        library: Mapping[str, TermFn],
        weights: Mapping[str, float] | None = None,
        where: str = "env.task.reward",
    ):
        nodes, self.normalize = resolve_terms(spec, presets, library, where)
        unknown = sorted(set(weights or {}) - set(nodes))
        if unknown:
            raise RewardConfigError(
                f"unknown reward term {unknown[0]!r} (env.task.weights); terms: {', '.join(nodes)}"
            )
        self.names: list[str] = []
        self.weights: list[float] = []
        self.functions: list[Callable[[Any, Mapping[str, Any]], float]] = []
        for name, node in nodes.items():
            node = dict(node or {})
            weight = (weights or {}).get(name, node.get("weight", 1.0))
            self._add(name, node, weight, library, where)
        self.total_weight = 0.0
        for w in self.weights:
            self.total_weight += w
        if self.normalize and not self.total_weight > 0:
            raise RewardConfigError(f"{where}: the weights of a normalized reward must sum to more than 0")
        self.episode_sums = np.zeros(len(self.names), np.float32)

    def _add(self, name: str, node: dict[str, Any], weight: Any, library: Mapping[str, TermFn], where: str):
        if not isinstance(weight, (int, float)) or isinstance(weight, bool) or not math.isfinite(weight):
            raise RewardConfigError(f"{where}.terms.{name}.weight must be a finite number, got {weight!r}")
        params = {k: v for k, v in node.items() if k not in TERM_KEYS}
        if "_target_" in node:  # a user's own term: named by the user's config, never by a received file
            function = _import_term(str(node["_target_"]), f"{where}.terms.{name}")
        elif name in library:
            function = library[name]
        else:
            raise RewardConfigError(
                f"unknown reward term {name!r} ({where}.terms); this task's terms: {', '.join(library)} "
                "(or give the term a _target_: your own function)"
            )
        try:  # a parameter the function does not take fails here, not at the first step
            inspect.signature(function).bind(None, {}, **params)
            bound = functools.partial(function, **params)
        except (TypeError, ValueError) as exc:
            raise RewardConfigError(f"{where}.terms.{name}: {exc}") from None
        self.names.append(name)
        self.weights.append(float(weight))
        self.functions.append(bound)

    def reset(self) -> None:
        self.episode_sums[:] = 0.0

    def __call__(self, task: Any, readings: Mapping[str, Any]) -> float:
        """The step's reward; each term's weighted value joins its episode sum."""
        total = 0.0
        for i, (weight, function) in enumerate(zip(self.weights, self.functions)):
            value = weight * function(task, readings)
            self.episode_sums[i] += value
            total += value
        return total / self.total_weight if self.normalize else total


def import_object(target: str, where: str) -> Any:
    """What a user's own config names (``module.name``), or one line saying why it cannot be had."""
    try:
        return locate(target)
    except NotImportable as exc:
        raise RewardConfigError(f"{where}._target_={target!r} cannot be imported ({exc})") from None


def _import_term(target: str, where: str) -> TermFn:
    """A user's term function: ``term(task, readings, **params) -> float``."""
    function = import_object(target, where)
    if not callable(function):
        raise RewardConfigError(f"{where}._target_={target!r} is not callable")
    return function
