"""The algorithms rlgrasp knows, found by package: ``rlgrasp/algos/<package>/`` with an ``ALGORITHM``.

Each algorithm is one package: its ``Algorithm`` class, its config schema and checks, its networks
and its terms, with ``configs/algo/<name>.yaml`` naming ``<name>_schema``. Everything that used to
list the algorithms (the config's validation and its ConfigStore, resume, the reader of received
files, the legacy loader) reads this registry instead, so adding an algorithm touches no file
outside its own package, its config file, tests and docs.

A package's ``__init__`` stays light (no torch): it holds an ``AlgorithmEntry`` of strings and
loads its class on first use (``lazy_attributes``), so that reading the registry (``rlgrasp.received``
does, for every received file) imports nothing heavy. The schema module (dataclasses and checks, no
torch) is imported when the config is registered or validated.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

#: One problem found in a config: (key, value, ok, what is allowed); kept when ``ok`` is False.
Check = tuple[str, Any, bool, str]


@dataclass(frozen=True)
class AlgorithmEntry:
    """An algorithm as the registry holds it, all strings: ``name`` is ``algo.name`` (and the
    checkpoint's key of its state), ``target`` the class configs and checkpoints name, ``schema`` the
    module holding ``SCHEMA`` (its config dataclass) and ``check(cfg, batch, camera)``; ``aliases``
    are class paths older files carry for the same class."""

    name: str
    target: str
    schema: str
    aliases: tuple[str, ...] = ()

    def schema_module(self) -> ModuleType:
        return importlib.import_module(self.schema)

    def schema_class(self) -> type:
        return self.schema_module().SCHEMA

    def check(self, cfg: Any, batch: int, camera: Any) -> list[Check]:
        """The checks of the training config ``cfg``'s ``algo`` node (``batch``: frames per batch)."""
        return self.schema_module().check(cfg, batch, camera)


@functools.cache
def algorithms() -> dict[str, AlgorithmEntry]:
    """Every registered algorithm by name: each sub-package of ``rlgrasp.algos`` with an ``ALGORITHM``."""
    import rlgrasp.algos as package

    found: dict[str, AlgorithmEntry] = {}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if not info.ispkg:
            continue
        entry = getattr(importlib.import_module(f"{package.__name__}.{info.name}"), "ALGORITHM", None)
        if isinstance(entry, AlgorithmEntry):
            found[entry.name] = entry
    return found


def entry(name: Any) -> AlgorithmEntry | None:
    return algorithms().get(name) if isinstance(name, str) else None


def names() -> str:
    """The registered names as a sentence lists them (``distill, ppo, sac or tqc``)."""
    listed = sorted(algorithms())
    return ", ".join(listed[:-1]) + " or " + listed[-1] if len(listed) > 1 else "".join(listed)


def unknown_name(name: Any) -> Check:
    """The one-line refusal of an ``algo.name`` no package registers, naming those that are."""
    choices = "|".join(sorted(algorithms()))
    return ("algo.name", name, False, f"must be {names()} (the algo group: algo={choices})")


def class_paths() -> dict[str, str]:
    """Short name -> class path of each algorithm (``rlgrasp.received.PARTS["algo"]``)."""
    return {name: e.target for name, e in algorithms().items()}


def alias_paths() -> dict[str, str]:
    """Older class path -> short name (``rlgrasp.received.ALIASES["algo"]``)."""
    return {alias: name for name, e in algorithms().items() for alias in e.aliases}


def lazy_attributes(package: str, module: str) -> Callable[[str], Any]:
    """A package's ``__getattr__`` that finds a missing name in ``module`` (imported on first use):
    ``rlgrasp.algos.sac.SAC``, the path configs and checkpoints name, resolves without the package
    importing torch when only its ``ALGORITHM`` entry is read."""

    def __getattr__(attribute: str) -> Any:
        if attribute.startswith("__"):
            raise AttributeError(f"module {package!r} has no attribute {attribute!r}")
        loaded = importlib.import_module(module)  # its own errors are its own, not a missing name
        if not hasattr(loaded, attribute):
            raise AttributeError(f"module {package!r} has no attribute {attribute!r}")
        return getattr(loaded, attribute)

    return __getattr__
