"""A part's settings from what a config, a checkpoint or a Python caller gives: ``None`` (the
defaults), the part's dataclass, or a mapping of its fields; an unknown key fails in one line naming
it and the keys there are."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")


def part_config(cls: type[T], value: Any, where: str) -> T:
    """``value`` as a ``cls`` (a dataclass); nested dataclass fields are read the same way."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if not isinstance(value, Mapping):
        raise ValueError(f"{where} must be a mapping of {', '.join(_names(cls))}, got {value!r}")
    unknown = sorted(set(value) - set(_names(cls)))
    if unknown:
        raise ValueError(f"unknown key {unknown[0]!r} in {where}; keys: {', '.join(_names(cls))}")
    values = {}
    for name, item in value.items():
        nested = _nested_class(cls, name)
        values[name] = part_config(nested, item, f"{where}.{name}") if nested else item
    return cls(**values)


def _names(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


def _nested_class(cls: type, name: str) -> type | None:
    """The dataclass a field's default factory makes, if it makes one."""
    field = next(f for f in dataclasses.fields(cls) if f.name == name)
    factory = field.default_factory
    return factory if isinstance(factory, type) and dataclasses.is_dataclass(factory) else None
