"""Search space: nested ``params`` of a sweep config -> Optuna distributions keyed by dotted training
keys, and a trial's values -> Hydra overrides."""

from __future__ import annotations

from collections.abc import Mapping
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
                float(spec["low"]), float(spec["high"]), log=bool(spec.get("log", False)),
                step=None if spec.get("step") is None else float(spec["step"]),
            )
        if kind == "int":
            return IntDistribution(
                int(spec["low"]), int(spec["high"]), log=bool(spec.get("log", False)),
                step=int(spec.get("step") or 1),
            )
        if kind == "categorical":
            choices = [list(c) if isinstance(c, (list, tuple)) else c for c in spec["choices"]]
            # Optuna stores categorical values as None/bool/int/float/str: lists travel as text.
            return CategoricalDistribution([_encode(c) for c in choices])
    except KeyError as exc:
        raise ValueError(f"sweep.params.{key}: type {kind} needs {exc.args[0]!r}") from None
    except ValueError as exc:
        raise ValueError(f"sweep.params.{key}: {exc}") from None
    raise ValueError(f"sweep.params.{key}: type must be float, int or categorical, got {kind!r}")


def parse_space(params: Mapping[str, Any]) -> dict[str, BaseDistribution]:
    """Dotted training key -> distribution, from the nested ``params`` mapping."""
    flat = flatten(params, leaf=_leaf)
    bad = [k for k, v in flat.items() if not _leaf(v)]
    if bad:
        raise ValueError(f"sweep.params: {bad} are not distributions (need a 'type' field)")
    return {key: distribution(key, spec) for key, spec in flat.items()}


def _encode(value: Any) -> Any:
    if isinstance(value, list):
        return "[" + ",".join(str(v) for v in value) + "]"
    return value


def suggest(trial: optuna.Trial, space: Mapping[str, BaseDistribution]) -> dict[str, Any]:
    """Sample every parameter of ``space`` on ``trial``."""
    out: dict[str, Any] = {}
    for key, d in space.items():
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
