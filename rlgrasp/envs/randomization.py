"""Declarative per-episode domain randomization.

Each parameter has a nominal value and a range; a preset is a named set of ranges. Values are drawn
once per episode from the env's own seeded generator, so the same seed gives the same episode, and
they go into ``info`` so training can log them and evaluation can break success down by them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rlgrasp.adr import NOT_BOUNDARY, AdrSettings, draw_boundary, parse_settings, start_ranges


@dataclass(frozen=True)
class Range:
    """A closed interval sampled uniformly, or log-uniformly when ``log`` is set."""

    low: float
    high: float
    log: bool = False

    def sample(self, rng: np.random.Generator) -> float:
        if self.low == self.high:
            return float(self.low)
        if self.log:
            return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))
        return float(rng.uniform(self.low, self.high))


@dataclass(frozen=True)
class ParamSpec:
    """What a parameter means physically: its nominal value and the bounds any range must respect."""

    nominal: float
    minimum: float = -math.inf
    maximum: float = math.inf
    integer: bool = False
    doc: str = ""


# Nominal values and hard bounds. The object pose parameters are the task's own variation and keep
# their range in every preset (an evaluation where every episode is identical proves nothing).
PARAMS: dict[str, ParamSpec] = {
    "object_size_scale": ParamSpec(1.0, 0.5, 2.0, doc="x the object's own size, snapped to 0.8-1.2 in 0.1"),
    "object_mass": ParamSpec(0.1, 1e-3, 5.0, doc="kg; without a range, the object's own mass"),
    "object_lateral_friction": ParamSpec(1.0, 0.0, 5.0, doc="without a range, the object's own"),
    "object_spinning_friction": ParamSpec(0.001, 0.0, 1.0),
    "object_rolling_friction": ParamSpec(0.0001, 0.0, 1.0),
    "object_restitution": ParamSpec(0.0, 0.0, 1.0),
    "finger_friction": ParamSpec(1.0, 0.0, 5.0),
    "joint_damping": ParamSpec(0.0, 0.0, 10.0, doc="arm joint damping"),
    "position_gain_scale": ParamSpec(1.0, 0.05, 5.0, doc="x nominal position-control gain"),
    "finger_force": ParamSpec(20.0, 1.0, 200.0, doc="N, finger motor force"),
    "gravity_z": ParamSpec(-9.81, -20.0, 0.0, doc="m/s^2"),
    "object_x": ParamSpec(0.0, -0.2, 0.2, doc="m, offset from the nominal object position"),
    "object_y": ParamSpec(0.0, -0.2, 0.2, doc="m, offset from the nominal object position"),
    "object_yaw": ParamSpec(0.0, -math.pi, math.pi, doc="rad"),
    "arm_pose_noise": ParamSpec(0.0, 0.0, 0.5, doc="rad, std of the start-pose noise"),
    "action_noise_episode": ParamSpec(0.0, 0.0, 1.0, doc="std of a per-episode action offset"),
    "action_noise_step": ParamSpec(0.0, 0.0, 1.0, doc="std of per-step action noise"),
    "action_delay": ParamSpec(0, 0, 5, integer=True, doc="control steps an action waits"),
    "obs_noise_episode": ParamSpec(0.0, 0.0, 1.0, doc="std of a per-episode observation offset"),
    "obs_noise_step": ParamSpec(0.0, 0.0, 1.0, doc="std of per-step observation noise"),
}

# The task's own variation: present in every preset, `none` included.
_TASK = {
    "object_x": Range(-0.1, 0.1),
    "object_y": Range(-0.1, 0.1),
    "object_yaw": Range(-math.pi, math.pi),
}

# Ranges within which the scripted grasp of the cube still succeeds nearly always
# (docs/benchmarks/objects.md#the-scripted-expert), plus modest sensing noise.
_DEFAULT = {
    **_TASK,
    "object_size_scale": Range(0.8, 1.2),
    "object_mass": Range(0.05, 0.5, log=True),
    "object_lateral_friction": Range(0.5, 1.5),
    "object_spinning_friction": Range(0.0, 0.005),
    "object_rolling_friction": Range(0.0, 0.0005),
    "object_restitution": Range(0.0, 0.2),
    "finger_friction": Range(0.8, 1.2),
    "joint_damping": Range(0.0, 1.0),
    "position_gain_scale": Range(0.7, 1.3),
    "finger_force": Range(10.0, 40.0),
    "gravity_z": Range(-10.3, -9.3),
    "arm_pose_noise": Range(0.02, 0.02),
    "action_noise_episode": Range(0.0, 0.03),
    "action_noise_step": Range(0.0, 0.03),
    "action_delay": Range(0, 1),
    "obs_noise_episode": Range(0.0, 0.002),
    "obs_noise_step": Range(0.0, 0.002),
}


def _widen(ranges: Mapping[str, Range], factor: float) -> dict[str, Range]:
    """Scale each range about its centre, clipped to the parameter's bounds (task pose excluded)."""
    out = {}
    for name, rng in ranges.items():
        if name in _TASK:
            out[name] = rng
            continue
        spec = PARAMS[name]
        mid, half = (rng.low + rng.high) / 2, (rng.high - rng.low) / 2 * factor
        low, high = max(spec.minimum, mid - half), min(spec.maximum, mid + half)
        if spec.integer:
            low, high = math.floor(low), math.ceil(high)
        out[name] = replace(rng, low=low, high=high)
    return out


PRESETS: dict[str, dict[str, Range]] = {
    "none": dict(_TASK),
    "default": _DEFAULT,
    "wide": _widen(_DEFAULT, 1.8),
}


def _as_range(name: str, value: Any) -> Range:
    if isinstance(value, Range):
        return value
    if isinstance(value, (int, float)):
        return Range(float(value), float(value))
    if isinstance(value, Mapping):
        unknown = set(value) - {"low", "high", "log"}
        if unknown or not {"low", "high"} <= set(value):
            raise ValueError(
                f"randomization parameter {name!r}: a range needs keys 'low', 'high' and "
                f"optionally 'log', got {sorted(value)}"
            )
        return Range(float(value["low"]), float(value["high"]), bool(value.get("log", False)))
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return Range(float(value[0]), float(value[1]))
    raise ValueError(
        f"randomization parameter {name!r}: expected a number, [low, high] or "
        f"{{low, high, log}}, got {value!r}"
    )


def _validate(name: str, rng: Range) -> None:
    if name not in PARAMS:
        raise ValueError(f"unknown randomization parameter {name!r}; valid parameters: {', '.join(PARAMS)}")
    spec = PARAMS[name]
    if not (math.isfinite(rng.low) and math.isfinite(rng.high)):
        raise ValueError(f"randomization parameter {name!r}: bounds must be finite, got {rng}")
    if rng.low > rng.high:
        raise ValueError(
            f"randomization parameter {name!r}: low ({rng.low}) is greater than high ({rng.high})"
        )
    if rng.low < spec.minimum or rng.high > spec.maximum:
        raise ValueError(
            f"randomization parameter {name!r}: range [{rng.low}, {rng.high}] is outside the "
            f"allowed [{spec.minimum}, {spec.maximum}]"
        )
    if rng.log and rng.low <= 0:
        raise ValueError(f"randomization parameter {name!r}: a log-uniform range needs low > 0")


class Randomizer:
    """Draws one episode's physical and sensing parameters.

    ``spec`` is a preset name, a YAML file holding a mapping (what an ADR run writes), or a mapping of
    parameter -> range that overrides a base preset (``{"preset": "none", "object_mass": [0.05, 1.0]}``;
    the base defaults to ``none``). A mapping's ``adr`` node (``rlgrasp.adr.parse_settings``) makes its
    parameters ADR's: they start at their nominal values (or ``adr.start``'s preset) and move when the
    learner calls ``set_ranges``, which also turns on boundary episodes: an env built from the config
    alone (an evaluation) samples the start ranges and pins nothing.
    """

    def __init__(self, spec: str | Mapping[str, Any] | None = "default"):
        self.ranges, self.adr = self._resolve(spec)
        self.boundary = NOT_BOUNDARY
        self._boundary_prob = 0.0

    @staticmethod
    def _resolve(spec: str | Mapping[str, Any] | None) -> tuple[dict[str, Range], AdrSettings | None]:
        if spec is None:
            spec = "none"
        if isinstance(spec, str) and spec.endswith((".yaml", ".yml")):
            return Randomizer._resolve(_load_file(spec))
        adr = None
        if isinstance(spec, str):
            if spec not in PRESETS:
                raise ValueError(
                    f"unknown randomization preset {spec!r}; valid presets: {', '.join(PRESETS)} "
                    "(or a .yaml file of ranges)"
                )
            ranges = dict(PRESETS[spec])
        elif isinstance(spec, Mapping):
            spec = dict(spec)
            base, adr_node = spec.pop("preset", "none"), spec.pop("adr", None)
            ranges = dict(Randomizer._resolve(base)[0])
            for name, value in spec.items():
                if name not in PARAMS:
                    raise ValueError(
                        f"unknown randomization parameter {name!r}; valid parameters: "
                        f"{', '.join(PARAMS)} (and 'preset', 'adr')"
                    )
                ranges[name] = _as_range(name, value)
            if adr_node is not None:
                adr = _adr_settings(adr_node)
                log = {p.name: p.log for p in adr.params}
                ranges.update({k: Range(*v, log=log[k]) for k, v in _adr_start(adr).items()})
        else:
            raise ValueError(
                f"randomization must be a preset name ({', '.join(PRESETS)}), a .yaml file or a mapping "
                f"of parameter ranges, got {spec!r}"
            )
        for name, rng in ranges.items():
            _validate(name, rng)
        return ranges, adr

    def set_ranges(self, ranges: Mapping[str, Any], boundary_prob: float) -> None:
        """The learner's current ADR ranges (``name -> (low, high)``) and boundary probability."""
        if self.adr is None:
            raise ValueError("set_ranges needs an ADR randomization (a spec with an 'adr' node)")
        for name, (low, high) in ranges.items():
            if name not in self.adr.names:
                raise ValueError(f"randomization parameter {name!r} is not one of ADR's: {self.adr.names}")
            self.ranges[name] = Range(float(low), float(high), self.ranges[name].log)
        self._boundary_prob = float(boundary_prob)

    def sample(self, rng: np.random.Generator) -> dict[str, float]:
        """One episode's values; parameters without a range take their nominal value. Under ADR the
        boundary draw comes first, from the same seeded generator: same seed, same episodes."""
        self.boundary = NOT_BOUNDARY
        if self.adr is not None:
            current = {name: (self.ranges[name].low, self.ranges[name].high) for name in self.adr.names}
            self.boundary = draw_boundary(rng, self.adr, current, self._boundary_prob)
        values = {}
        for name, spec in PARAMS.items():  # fixed order: same seed, same draws
            r = self.ranges.get(name)
            if r is None:
                values[name] = int(spec.nominal) if spec.integer else spec.nominal
            elif spec.integer:
                values[name] = int(rng.integers(int(r.low), int(r.high) + 1))
            else:
                values[name] = r.sample(rng)
        if self.boundary != NOT_BOUNDARY:
            param, bound = self.adr.decode(self.boundary)
            pinned = (self.ranges[param.name].low, self.ranges[param.name].high)[bound]
            values[param.name] = int(pinned) if PARAMS[param.name].integer else float(pinned)
        return values

    def info(self) -> dict[str, int]:
        """What the learner reads from each step's ``info``: the episode's ADR boundary code."""
        return {} if self.adr is None else {"adr_boundary": self.boundary}


def _load_file(path: str) -> Mapping[str, Any]:
    """A YAML file of ranges (``{preset: ..., name: {low, high}}``), as an ADR run writes its final ones."""
    try:
        spec = yaml.safe_load(Path(path).read_text())
    except OSError as exc:
        raise ValueError(f"randomization file {path!r}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        reason = str(exc).splitlines()[0]
        raise ValueError(f"randomization file {path!r}: not valid YAML ({reason})") from None
    if not isinstance(spec, Mapping) or "adr" in spec:
        raise ValueError(f"randomization file {path!r}: expected a mapping of parameter ranges")
    return spec


def _adr_settings(node: Any) -> AdrSettings:
    """ADR's settings, each parameter checked against what the env knows of it."""
    adr = parse_settings(node)
    for p in adr.params:
        if p.name not in PARAMS or p.name in _TASK:
            valid = [n for n in PARAMS if n not in _TASK]
            raise ValueError(f"randomization adr parameter {p.name!r}: not one of {', '.join(valid)}")
        spec = PARAMS[p.name]
        if p.low_limit < spec.minimum or p.high_limit > spec.maximum:
            raise ValueError(
                f"randomization adr parameter {p.name!r}: limits [{p.low_limit}, {p.high_limit}] are "
                f"outside the physically allowed [{spec.minimum}, {spec.maximum}]"
            )
        if spec.integer and (p.step != int(p.step) or p.nominal != int(p.nominal)):
            raise ValueError(f"randomization adr parameter {p.name!r}: an integer parameter needs integers")
    if adr.start != "nominal" and adr.start not in PRESETS:
        raise ValueError(
            f"randomization adr.start={adr.start!r}: must be nominal or a preset ({', '.join(PRESETS)})"
        )
    return adr


def _adr_start(adr: AdrSettings) -> dict[str, tuple[float, float]]:
    preset = None if adr.start == "nominal" else PRESETS[adr.start]
    return start_ranges(adr, {k: (r.low, r.high) for k, r in (preset or {}).items()})
