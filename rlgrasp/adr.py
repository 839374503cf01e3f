"""Automatic domain randomization (ADR): ranges that widen while the policy succeeds at their bounds.

Pure logic, no simulator: the settings a config gives, the learner's state (ranges and per-bound
buffers of boundary-episode outcomes) and the draw that makes an episode a boundary episode. The env
side (``rlgrasp.envs.randomization``) samples from the ranges the learner pushes; the training side
(``rlgrasp.train.collection.adr_sync``) feeds outcomes in and pushes ranges out. Algorithm: OpenAI et
al. 2019, "Solving Rubik's Cube with a Robot Hand", Algorithm 1; docs/adr.md explains the settings.

A boundary is coded as one integer, ``2 * parameter_index + bound`` (bound 0 low, 1 high; -1: not a
boundary episode), so that it travels through ``info`` and a tensordict as a plain number.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

BOUNDS = ("low", "high")
NOT_BOUNDARY = -1
#: Widths below this count as this wide in the entropy: a range still at its nominal value has width
#: 0 and log(0) is -inf.
MIN_WIDTH = 1e-6
_SETTINGS = {"params", "start", "boundary_prob", "buffer_size", "low_threshold", "high_threshold"}
_PARAM_KEYS = {"nominal", "limits", "step", "integer", "log"}


@dataclass(frozen=True)
class AdrParam:
    """One randomized parameter: where it starts, how far it may go, and how far one move takes it."""

    name: str
    nominal: float
    low_limit: float
    high_limit: float
    step: float
    integer: bool = False
    log: bool = False  # episodes draw log-uniformly within the range (as a preset's mass does)


@dataclass(frozen=True)
class AdrSettings:
    """The config's ``adr`` node, checked. ``start``: ``nominal`` or a preset name to begin from."""

    params: tuple[AdrParam, ...]
    start: str = "nominal"
    boundary_prob: float = 0.5
    buffer_size: int = 10
    low_threshold: float = 0.4
    high_threshold: float = 0.7

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.params]

    def decode(self, code: int) -> tuple[AdrParam, int]:
        """The parameter and bound (0 low, 1 high) of a boundary code."""
        return self.params[code // 2], code % 2


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _param(name: str, node: Any) -> AdrParam:
    where = f"randomization adr parameter {name!r}"
    if not isinstance(node, Mapping):
        raise ValueError(f"{where}: expected {{nominal, limits: [low, high], step}}, got {node!r}")
    missing, unknown = {"nominal", "limits", "step"} - set(node), set(node) - _PARAM_KEYS
    if missing or unknown:
        what = f"needs {sorted(missing)}" if missing else f"unknown keys {sorted(unknown)}"
        raise ValueError(f"{where}: {what}; keys are nominal, limits: [low, high], step (and integer, log)")
    nominal, limits = _number(f"{where}: nominal", node["nominal"]), node["limits"]
    if isinstance(limits, str) or not isinstance(limits, Sequence) or len(limits) != 2:
        raise ValueError(f"{where}: limits must be [low, high], got {limits!r}")
    low, high = (_number(f"{where}: limits", v) for v in limits)
    if not low <= nominal <= high:
        raise ValueError(f"{where}: limits [{low}, {high}] exclude the nominal value {nominal}")
    step = _number(f"{where}: step", node["step"])
    if step <= 0:
        raise ValueError(f"{where}: step must be > 0, got {step}")
    log = bool(node.get("log", False))
    if log and low <= 0:
        raise ValueError(f"{where}: a log-uniform range needs limits above 0, got [{low}, {high}]")
    return AdrParam(name, nominal, low, high, step, bool(node.get("integer", False)), log)


def parse_settings(node: Mapping[str, Any]) -> AdrSettings:
    """``AdrSettings`` from a config node; ``ValueError`` naming the first bad key."""
    if not isinstance(node, Mapping):
        raise ValueError(f"randomization adr: expected a mapping of settings, got {node!r}")
    unknown = set(node) - _SETTINGS
    if unknown:
        raise ValueError(f"randomization adr: unknown keys {sorted(unknown)}; keys are {sorted(_SETTINGS)}")
    params = node.get("params") or {}
    if not isinstance(params, Mapping) or not params:
        raise ValueError("randomization adr.params: must map parameters to {nominal, limits, step}")
    defaults = AdrSettings(params=())
    p = _number("randomization adr.boundary_prob", node.get("boundary_prob", defaults.boundary_prob))
    lo = _number("randomization adr.low_threshold", node.get("low_threshold", defaults.low_threshold))
    hi = _number("randomization adr.high_threshold", node.get("high_threshold", defaults.high_threshold))
    size = node.get("buffer_size", defaults.buffer_size)
    checks = [
        ("boundary_prob", p, 0 <= p <= 1, "must be in [0, 1]"),
        ("low_threshold", lo, 0 <= lo <= 1, "must be in [0, 1]"),
        ("high_threshold", hi, 0 <= hi <= 1, "must be in [0, 1]"),
        ("low_threshold", lo, lo < hi, f"must be below high_threshold ({hi})"),
        (
            "buffer_size",
            size,
            isinstance(size, int) and not isinstance(size, bool) and size >= 1,
            "must be an integer >= 1",
        ),
    ]
    for key, value, ok, allowed in checks:
        if not ok:
            raise ValueError(f"randomization adr.{key}={value!r}: {allowed}")
    start = str(node.get("start", defaults.start))
    return AdrSettings(tuple(_param(str(k), v) for k, v in params.items()), start, p, int(size), lo, hi)


def is_fixed(param: AdrParam, bound: int, value: float) -> bool:
    """A bound at its nominal value and at its hard limit can neither widen nor narrow."""
    limit = param.high_limit if bound else param.low_limit
    return value == limit == param.nominal


def draw_boundary(
    rng: np.random.Generator, settings: AdrSettings, ranges: Mapping[str, tuple[float, float]], prob: float
) -> int:
    """With probability ``prob`` a boundary code drawn uniformly among the bounds that can move, else
    ``NOT_BOUNDARY``. Bounds that cannot move are skipped: on a CPU budget every boundary episode
    spent on them would be lost to the ones that can."""
    if prob <= 0 or rng.random() >= prob:
        return NOT_BOUNDARY
    codes = [
        2 * i + b
        for i, p in enumerate(settings.params)
        for b in (0, 1)
        if not is_fixed(p, b, ranges[p.name][b])
    ]
    return int(codes[rng.integers(len(codes))]) if codes else NOT_BOUNDARY


def start_ranges(settings: AdrSettings, preset: Mapping[str, tuple[float, float]] | None) -> dict:
    """Each parameter's first range: its nominal value, or the preset's range widened to include the
    nominal value (narrowing stops there) and clipped to the hard limits."""
    out = {}
    for p in settings.params:
        low, high = (preset or {}).get(p.name, (p.nominal, p.nominal))
        out[p.name] = (max(p.low_limit, min(low, p.nominal)), min(p.high_limit, max(high, p.nominal)))
    return out


class AdrState:
    """The learner's ADR state: current ranges and one buffer of outcomes per bound."""

    def __init__(self, settings: AdrSettings, start: Mapping[str, tuple[float, float]] | None = None) -> None:
        self.settings = settings
        first = start or start_ranges(settings, None)
        self.ranges: dict[str, list[float]] = {p.name: list(first[p.name]) for p in settings.params}
        self.buffers: dict[int, list[float]] = {code: [] for code in range(2 * len(settings.params))}
        self.moves = 0

    def record(self, code: int, success: float) -> str | None:
        """Add one boundary episode's outcome; when its buffer is full, move the bound (and say how)."""
        buffer = self.buffers[code]
        buffer.append(float(success))
        if len(buffer) < self.settings.buffer_size:
            return None
        rate = sum(buffer) / len(buffer)
        buffer.clear()
        if rate >= self.settings.high_threshold:
            return self._move(code, widen=True, rate=rate)
        if rate <= self.settings.low_threshold:
            return self._move(code, widen=False, rate=rate)
        return None

    def _move(self, code: int, widen: bool, rate: float) -> str | None:
        param, bound = self.settings.decode(code)
        old = self.ranges[param.name][bound]
        outward = 1.0 if bound else -1.0  # the high bound widens upwards, the low one downwards
        new = old + (outward if widen else -outward) * param.step
        limit = param.high_limit if bound else param.low_limit
        new = min(new, limit) if bound else max(new, limit)  # never past the hard limit
        new = max(new, param.nominal) if bound else min(new, param.nominal)  # nor inside the nominal
        new = round(new, 10)  # steps of 0.1 in binary floats would drift (0.30000000000000004)
        if new == old:
            return None
        self.ranges[param.name][bound] = new
        self.moves += 1
        return f"{param.name} {BOUNDS[bound]} {old:g} -> {new:g} (success {rate:.2f})"

    def entropy(self) -> float:
        """Mean log range width in nats per dimension (the paper's progress measure)."""
        widths = [max(high - low, MIN_WIDTH) for low, high in self.ranges.values()]
        return float(np.mean(np.log(widths)))

    def range_tuples(self) -> dict[str, tuple[float, float]]:
        return {name: (low, high) for name, (low, high) in self.ranges.items()}

    def state_dict(self) -> dict[str, Any]:
        return {
            "ranges": {k: list(v) for k, v in self.ranges.items()},
            "buffers": {k: list(v) for k, v in self.buffers.items()},
            "moves": self.moves,
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Continue from a checkpoint; parameters the checkpoint lacks keep their current range."""
        for name, value in state["ranges"].items():
            if name in self.ranges:
                self.ranges[name] = [float(value[0]), float(value[1])]
        for code, outcomes in state["buffers"].items():
            if int(code) in self.buffers:
                self.buffers[int(code)] = [float(x) for x in outcomes]
        self.moves = int(state.get("moves", 0))
