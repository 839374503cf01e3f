"""What every entry point does with its command line before it runs: one spelling for the objects,
and bad input (a command line Hydra refuses, a flag argparse refuses, an output path that cannot be
written) in one line naming the override and what is allowed.

``objects=<set>`` selects a file of the ``objects`` config group, which sets ``env.objects``. Hydra
treats a dict value for a group's name as a key of the primary config instead (training has no
top-level ``objects``: "Key 'objects' not in 'TrainConfig'"), and a list value as several files of the
group, the last one winning: neither reaches the env as given. So ``objects={paths:[...]}`` and
``objects=[a,b]`` are rewritten to ``env.objects=...`` before Hydra reads the command line. In
evaluation ``env`` holds only the env keywords given over the checkpoint's, so there every
``env.<key>=`` becomes ``++env.<key>=`` (add or override): the spelling training uses works as is.

Hydra prints a refused command line over several lines (the options, its search path, a hint about
``HYDRA_FULL_ERROR``); ``explain`` turns its exception into one.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

# The parser hydra.main itself reads sys.argv with (not public API): flags are read exactly as it will.
from hydra._internal.utils import get_args_parser
from hydra.errors import HydraException, MissingConfigException, OverrideParseException
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from rlgrasp.compose import compose_config
from rlgrasp.config import CONFIG_DIR
from rlgrasp.legacy import ENV_KEYS, moved_algo_key

#: Groups whose files set one ``env`` key; a dict (or, for objects, a list) value is that key's value.
ENV_GROUPS = {"objects": ("{", "["), "randomization": ("{",), "robot": ("{",)}
#: An option of each group setting a plain name: chosen first, so that the value replaces what an
#: experiment's option set (Hydra merges a dict into a dict, and refuses one into a list:
#: experiment=grasp_objects_ppo's objects are a list).
NEUTRAL = {"objects": "cube", "randomization": "default", "robot": "panda"}
#: The groups of rlgrasp's own env's parts (configs/env/grasp.yaml's defaults): env=gym has none of them.
ENV_PARTS = ("task", "randomization", "objects", "robot", "cameras", "visual")
#: Hydra's flags after which the command line is not one run's overrides (help, multirun, ...).
_NOT_A_RUN = (
    "help",
    "hydra_help",
    "cfg",
    "info",
    "shell_completion",
    "multirun",
    "experimental_rerun",
    "config_path",
    "config_name",
    "config_dir",
)


class CommandLineError(ValueError):
    """A command line that does not compose; the message is one line."""


def rewrite(overrides: Sequence[str], open_env: bool = False) -> list[str]:
    """``objects={...}`` / ``objects=[...]`` (and ``randomization={...}`` where the config has no
    top-level key of that name) -> ``env.<group>=...``, which replaces the group's value; with
    ``open_env`` (``env`` is a dict of extra keywords, as in evaluation) ``env.<key>=`` ->
    ``++env.<key>=``."""
    out = []
    for item in overrides:
        key, eq, value = item.partition("=")
        name = key.lstrip("+")
        if eq and name in ENV_GROUPS and value.startswith(ENV_GROUPS[name]):
            if open_env and name in ("objects", "robot"):  # nothing to replace: env holds only what is given
                item = f"++env.{name}={value}"
            elif not open_env:  # (evaluation has its own `randomization` key)
                out.append(f"{name}={NEUTRAL[name]}")
                item = f"env.{name}={value}"
        elif eq and open_env and key.startswith("env."):
            item = f"++{item}"
        out.append(item)
    return out


def _key_of(override: str) -> str:
    return override.lstrip("+~").split("=", 1)[0]


def _shown(full_key: str, overrides: Sequence[str]) -> str:
    """The override that set ``full_key`` as typed (``algo.optim.lr=abc``; the last one, as Hydra applies
    them in order), else the key."""
    return next((o.lstrip("+~") for o in reversed(overrides) if _key_of(o) == full_key), full_key)


def explain(exc: BaseException, overrides: Sequence[str] = (), root: str = "the config") -> str:
    """One line for a Hydra composition error (or OmegaConf's, from a merge): the override, what is
    wrong, what is allowed. ``root`` names the top node in "<root> has <keys>"."""
    if isinstance(exc, MissingConfigException) and exc.missing_cfg_file:
        group, _, option = exc.missing_cfg_file.rpartition("/")
        options = [o for o in exc.options or [] if not o.endswith("_schema")]  # the schemas are internal
        return f"{group}={option}: no such option; {group} is one of {', '.join(options)}"
    if isinstance(exc, OverrideParseException):
        return f"{exc.override}: not a valid override ({exc.message.splitlines()[0]})"
    cause = exc if isinstance(exc, OmegaConfBaseException) else exc.__cause__
    if isinstance(cause, OmegaConfBaseException) and cause.full_key:
        shown = _shown(cause.full_key, overrides)
        parent = cause.parent_node
        if "not in" in str(cause.msg) and parent is not None:
            keys = [str(k) for k in parent.keys() if k != "hydra"]
            where = cause.full_key.rpartition(".")[0]
            line = f"{shown}: unknown key '{cause.key}'; {where or root} has {', '.join(keys) or 'no keys'}"
            # A node with no schema (env.camera, a robot mapping) takes new keys, which its own
            # reader checks; Hydra wants them marked as new.
            if where and OmegaConf.get_type(parent) is dict:
                line += f" (a new key of {where}: +{shown})"
            return line + _moved(cause.full_key, parent)
        return f"{shown}: {str(cause.msg).splitlines()[0]}" + _moved(cause.full_key, parent)
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    part = re.match(r"Could not override '(\w+)'\. No match", lines[0]) if lines else None
    if part and part.group(1) in ENV_PARTS:  # env=gym: rlgrasp's own env parts are env=grasp's groups
        return (
            f"{_shown(part.group(1), overrides)}: a part of rlgrasp's own env (env=grasp); another "
            "package's env (env=gym) takes env.id and its own keywords (env.<key>)"
        )
    return "; ".join(lines[:3]) or type(exc).__name__


def _moved(full_key: str, parent: Any) -> str:
    """Where a flat ``algo`` or ``env`` key of before lives now (``algo.lr`` -> ``algo.optim.lr``,
    ``env.control_mode`` -> ``env.control.mode``), as a clause."""
    where, _, key = full_key.rpartition(".")
    if where == "env" and key in ENV_KEYS:
        return f"; env.{key} is env.{ENV_KEYS[key]} now"
    if where != "algo":
        return ""
    moved = moved_algo_key(key, parent.get("name") if parent is not None else None)
    return f"; algo.{key} is algo.{moved} now" if moved else ""


def check(config_name: str, overrides: Sequence[str], config_dir: str | Path = CONFIG_DIR) -> None:
    """Compose ``config_name`` with ``overrides`` as its entry point will: ``CommandLineError`` (one
    line) when Hydra refuses them."""
    try:
        compose_config(config_name, list(overrides), config_dir)
    except (HydraException, OmegaConfBaseException) as exc:
        raise CommandLineError(explain(exc, overrides)) from None


def _run_overrides(argv: Sequence[str]) -> list[str] | None:
    """The overrides of a plain run, or ``None`` when Hydra's flags ask for something else."""
    try:
        args = get_args_parser().parse_args(list(argv))
    except SystemExit:  # a flag Hydra does not know: its own message follows
        return None
    if any(getattr(args, flag, None) for flag in _NOT_A_RUN):
        return None
    return list(args.overrides)


Main = Callable[..., Any]


def entry_point(config_name: str, open_env: bool = False) -> Callable[[Main], Main]:
    """For a ``@hydra.main`` function: rewrite ``sys.argv`` (``rewrite``), then refuse a command line
    that does not compose with one line and exit code 1 (Hydra's own code for it), before Hydra
    creates anything."""

    def wrap(hydra_main: Main) -> Main:
        @functools.wraps(hydra_main)
        def main(*args: Any, **kwargs: Any) -> Any:
            sys.argv[1:] = rewrite(sys.argv[1:], open_env)
            overrides = _run_overrides(sys.argv[1:])
            if overrides is not None:
                try:
                    check(config_name, overrides)
                except CommandLineError as exc:
                    print(f"error: {exc}", file=sys.stderr)
                    sys.exit(1)
            return hydra_main(*args, **kwargs)

        return main

    return wrap


def unwritable(path: str | Path, folder: bool = False) -> str | None:
    """Why ``path`` could not be written (``None``: it can), creating nothing: the nearest existing
    ancestor must be a writable directory (``folder``: and ``path`` itself, if it exists, a folder).
    Checked before any work, so that a typo in an output path is not a writer's traceback at the end."""
    target = Path(path).expanduser().absolute()
    existing = next(p for p in (target, *target.parents) if p.exists())
    if (existing != target or folder) and not existing.is_dir():
        return f"{existing} is not a directory"
    where = existing if existing.is_dir() else existing.parent  # an existing file is replaced
    if not os.access(where, os.W_OK | os.X_OK):
        return f"{where} is not writable"
    return None


class OneLineParser(argparse.ArgumentParser):
    """``argparse`` whose usage errors are one line (its default prints the usage first)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"error: {message} (see {self.prog} --help)", file=sys.stderr)
        sys.exit(2)
