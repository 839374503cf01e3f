"""A dotted name from the user's own config or command line, as the object it names, or one short
line saying why it cannot be had.

Hand-written rather than Hydra's ``_locate`` / ``get_object``: theirs log or raise errors of several
lines with a hint about HYDRA_FULL_ERROR, where a bad value here gets one line naming the key.
Only names the user wrote come here: a received file's names never do (rlgrasp.received)."""

from __future__ import annotations

import importlib
from typing import Any


class NotImportable(Exception):
    """Why a dotted name cannot be had, in a few words (the message)."""


def locate(target: str) -> Any:
    """``module.name`` (a class's attribute included: ``module.Class.method``), imported.
    The longest prefix that imports is the module, the rest are attributes of it."""
    parts = target.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        module = ".".join(parts[:cut])
        try:
            found: Any = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name and (module == exc.name or module.startswith(exc.name + ".")):
                continue  # no such module: a shorter prefix may be the module, the rest its names
            raise NotImportable(f"importing {module} failed ({type(exc).__name__}: {exc})") from None
        except Exception as exc:  # noqa: BLE001 - the user's own module failing as it loads
            raise NotImportable(f"importing {module} failed ({type(exc).__name__}: {exc})") from None
        for name in parts[cut:]:
            if not hasattr(found, name):
                raise NotImportable(f"{module} has no {name!r}")
            found = getattr(found, name)
        return found
    raise NotImportable(f"no module {parts[0]!r} is installed")
