"""Search space: nested ``params`` of a sweep config -> Optuna distributions keyed by dotted training
keys, and a trial's values -> Hydra overrides.

A categorical whose ``choices`` is a mapping is a named choice that sets several training keys, e.g.
``control: {type: categorical, choices: {ee_delta_yaw: {env: {control: {mode: ee_delta, ee_yaw: true}}},
...}}``: Optuna samples the names; each name stands for the keys under it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import optuna
from optuna.distributions import (
    BaseDistribution,
    CategoricalDistribution,
    FloatDistribution,
    IntDistribution,
)

from rlgrasp.utils import flatten


def _leaf(node: Any) -> bool:
    return isinstance(node, Mapping) and "type" in node


def distribution(key: str, spec: Mapping[str, Any]) -> BaseDistribution:
    """One distribution; the error names the key and what was expected."""
    kind = spec.get("type")
    extra = set(spec) - {"type", "low", "high", "log", "step", "choices"}
    if extra:
        raise ValueError(f"sweep.params.{key}: unknown fields {sorted(extra)}")
    try:
        if kind == "float":
            return FloatDistribution(
                float(spec["low"]),
                float(spec["high"]),
                log=bool(spec.get("log", False)),
                step=None if spec.get("step") is None else float(spec["step"]),
            )
        if kind == "int":
            return IntDistribution(
                int(spec["low"]),
                int(spec["high"]),
                log=bool(spec.get("log", False)),
                step=int(spec.get("step") or 1),
            )
        if kind == "categorical":
            choices = [list(c) if isinstance(c, (list, tuple)) else c for c in spec["choices"]]
            # Optuna stores categorical values as None/bool/int/float/str: lists travel as text.
            return CategoricalDistribution([encode_choice(c) for c in choices])
    except KeyError as exc:
        raise ValueError(f"sweep.params.{key}: type {kind} needs {exc.args[0]!r}") from None
    except ValueError as exc:
        raise ValueError(f"sweep.params.{key}: {exc}") from None
    raise ValueError(f"sweep.params.{key}: type must be float, int or categorical, got {kind!r}")


@dataclass(frozen=True)
class Space:
    """The parameters Optuna samples (name -> distribution; a name is a dotted training key, or a
    named choice's) and what each named choice sets (name -> choice -> {training key: value})."""

    dists: dict[str, BaseDistribution]
    sets: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)

    def __contains__(self, name: object) -> bool:
        return name in self.dists

    def training_values(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """Training key -> value for a trial's parameters; ``ValueError`` for an unknown named choice."""
        out: dict[str, Any] = {}
        for name, value in params.items():
            if name not in self.sets:
                out[name] = value
            elif value in self.sets[name]:
                out.update(self.sets[name][value])
            else:
                raise ValueError(f"{name}={value!r}: must be one of {', '.join(self.sets[name])}")
        return out

    def overrides(self, params: Mapping[str, Any]) -> list[str]:
        return to_overrides(self.training_values(params))


def _named_choices(key: str, spec: Mapping[str, Any]) -> dict[str, dict[str, Any]] | None:
    """A categorical's ``choices`` given as a mapping: name -> the training keys it sets (flattened)."""
    choices = spec.get("choices")
    if spec.get("type") != "categorical" or not isinstance(choices, Mapping):
        return None
    out = {}
    for name, keys in choices.items():
        if not isinstance(keys, Mapping) or not keys:
            raise ValueError(
                f"sweep.params.{key}.choices.{name}: must map training keys to values, "
                f"e.g. {{env: {{control: {{mode: ee_delta}}}}}}"
            )
        out[str(name)] = flatten(keys)
    return out


def parse_space(params: Mapping[str, Any]) -> Space:
    """The search space of the nested ``params`` mapping."""
    flat = flatten(params, leaf=_leaf)
    bad = [k for k, v in flat.items() if not _leaf(v)]
    if bad:
        raise ValueError(f"sweep.params: {bad} are not distributions (need a 'type' field)")
    dists, sets = {}, {}
    for key, spec in flat.items():
        named = _named_choices(key, spec)
        if named is not None:
            sets[key] = named
            spec = {**spec, "choices": list(named)}
        dists[key] = distribution(key, spec)
    return Space(dists, sets)


def encode_choice(value: Any) -> Any:
    """A categorical value as Optuna stores it: a list as its override text, ``[256,256]``."""
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(str(v) for v in value) + "]"
    return value


def suggest(trial: optuna.Trial, space: Space) -> dict[str, Any]:
    """Sample every parameter of ``space`` on ``trial``."""
    out: dict[str, Any] = {}
    for key, d in space.dists.items():
        if isinstance(d, FloatDistribution):
            out[key] = trial.suggest_float(key, d.low, d.high, log=d.log, step=d.step)
        elif isinstance(d, IntDistribution):
            out[key] = trial.suggest_int(key, d.low, d.high, log=d.log, step=d.step)
        else:
            out[key] = trial.suggest_categorical(key, d.choices)
    return out


def override_value(value: Any) -> str:
    """A value in Hydra's override grammar (floats in full precision, None as null)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return repr(value)
    return str(value)


def to_overrides(params: Mapping[str, Any]) -> list[str]:
    return [f"{key}={override_value(value)}" for key, value in params.items()]
