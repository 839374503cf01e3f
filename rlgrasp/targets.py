"""What a config read from a file may name: rlgrasp's own classes, at the nodes that build them.

A checkpoint loads with ``weights_only=True`` and cannot run code while it loads; its ``config`` is
then rebuilt with Hydra's ``instantiate`` (the env, and on resume the collector, the logger and the
algorithm), which calls whatever ``_target_`` a node names, with whatever ``_args_`` it gives, at any
depth. Hydra refuses a few targets (``os.system``) and not others (``builtins.open`` truncates a file
of the sender's choosing). So a config that came from a file is data until this module has checked
it: a ``_target_`` may stand only at the top of a node that rlgrasp builds (``env``, ``collector``,
``logger``, ``algo``, and each of ``algo.terms``), and must name one of the classes below; no other
instantiation key may appear anywhere. A class of your own is trusted when
your own command line's config names it (``trusted``, on resume) or your shell lists it in
``RLGRASP_TRUSTED_TARGETS``, never because a received file does.

This module imports nothing of rlgrasp's: every reader can use it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

#: The classes a received config may name, by the node that builds them.
REGISTRY: dict[str, frozenset[str]] = {
    "env": frozenset({"rlgrasp.envs.PandaGraspEnv", "rlgrasp.envs.GraspEnv"}),
    "collector": frozenset(
        {
            "rlgrasp.train.collectors.ProcessCollector",
            "rlgrasp.train.collectors.SingleCollector",
            "rlgrasp.train.collectors.RayCollector",
        }
    ),
    "logger": frozenset(
        {
            "rlgrasp.train.logger.TensorBoardLogger",
            "rlgrasp.train.logger.ConsoleLogger",
            "rlgrasp.train.trackers.WandbLogger",
            "rlgrasp.train.trackers.MlflowLogger",
        }
    ),
    "algo": frozenset({"rlgrasp.algos.ppo.PPO", "rlgrasp.algos.sac.SAC", "rlgrasp.vision.distill.DAgger"}),
    "env.task": frozenset(
        {
            "rlgrasp.envs.tasks.LiftTask",
            "rlgrasp.envs.tasks.PickPlaceTask",
            "rlgrasp.envs.tasks.PushTask",
            "rlgrasp.envs.tasks.StackTask",
        }
    ),
}
#: The classes an algorithm's auxiliary term (a node of ``algo.terms``) may name.
TERMS = frozenset(
    {"rlgrasp.demos.bc.Imitation", "rlgrasp.vision.teacher_term.TeacherImitation", "rlgrasp.train.rnd.RND"}
)
TERMS_NODE = "algo.terms"
#: Hydra's keys that make a node callable or change how it is called.
INSTANTIATE_KEYS = ("_target_", "_args_", "_partial_", "_recursive_", "_convert_")


class UntrustedConfigError(ValueError):
    """A config read from a file names something rlgrasp does not build; the message is one line."""


def check_received_config(config: Any, source: str, trusted: Iterable[str] = ()) -> None:
    """Refuse ``config`` (a plain dict, as checkpoints store it) if it would make ``instantiate``
    call anything but rlgrasp's own classes at their nodes (or a class in ``trusted``)."""
    if not isinstance(config, Mapping):
        return
    trusted = frozenset(trusted) | env_trusted_targets()
    for node, value in _built_nodes(config).items():
        allowed = _allowed_at(node)
        if "_target_" in value and value["_target_"] not in allowed | trusted:
            raise UntrustedConfigError(
                f"{source}: refused: config.{node}._target_={value['_target_']!r} is not a class rlgrasp "
                f"builds (allowed: {', '.join(sorted(allowed))})"
            )
    for path, key, value in _entries(config, ""):
        if isinstance(value, str) and "${" in value:
            raise UntrustedConfigError(
                f"{source}: refused: {_where(path, key)} holds an interpolation (${{...}}); a saved config "
                "is stored resolved, so this one was made by hand"
            )
        if key in INSTANTIATE_KEYS and not (_builds(path) and key == "_target_"):
            raise UntrustedConfigError(
                f"{source}: refused: {_where(path, key)} would be called when the config is built "
                "(a file's config may name a class only at env, env.task, collector, logger, algo or "
                "algo.terms.*)"
            )


def _builds(path: str) -> bool:
    """Whether rlgrasp builds the node at ``path`` from its ``_target_``."""
    return path in REGISTRY or (path.startswith(TERMS_NODE + ".") and path.count(".") == 2)


def _allowed_at(path: str) -> frozenset[str]:
    return REGISTRY.get(path, TERMS)


def _built_nodes(config: Mapping) -> dict[str, Mapping]:
    """Each node rlgrasp builds from a ``_target_``, by its path: the top ones and ``algo``'s terms."""
    nodes = {n: config[n] for n in REGISTRY if isinstance(config.get(n), Mapping)}
    task = nodes.get("env", {}).get("task")
    if isinstance(task, Mapping):
        nodes["env.task"] = task
    terms = nodes.get("algo", {}).get("terms")
    if isinstance(terms, Mapping):
        nodes.update({f"{TERMS_NODE}.{k}": v for k, v in terms.items() if isinstance(v, Mapping)})
    return nodes


#: Classes of your own that files may name, comma-separated (e.g. the env your runs were trained on).
TRUSTED_ENV_VAR = "RLGRASP_TRUSTED_TARGETS"


def env_trusted_targets() -> frozenset[str]:
    """The classes the user listed in ``RLGRASP_TRUSTED_TARGETS``: their own env or backend, set in
    their own shell, never by a file."""
    return frozenset(t.strip() for t in os.environ.get(TRUSTED_ENV_VAR, "").split(",") if t.strip())


def _entries(node: Any, path: str) -> Iterable[tuple[str, str, Any]]:
    """Every (path of the container, key or index, value) of a config, at any depth."""
    items = (
        node.items()
        if isinstance(node, Mapping)
        else enumerate(node)
        if isinstance(node, (list, tuple))
        else ()
    )
    for key, value in items:
        yield path, str(key) if isinstance(node, Mapping) else f"[{key}]", value
        child = (f"{path}.{key}" if path else str(key)) if isinstance(node, Mapping) else f"{path}[{key}]"
        yield from _entries(value, child)


def _where(path: str, key: str) -> str:
    if key.startswith("["):
        return f"config.{path}{key}"
    return f"config.{path}.{key}" if path else f"config.{key}"


def trusted_targets(config: Any) -> set[str]:
    """The ``_target_`` of each node of the user's own composed config (what their command line
    chose, e.g. a collector class of their own), to pass as ``trusted`` for a file read beside it."""
    return {str(node["_target_"]) for node in _built_nodes(config).values() if "_target_" in node}


#: What ``TensorDict.memmap`` writes for a TensorDict of plain tensors.
_PLAIN_TYPE = "<class 'tensordict._td.TensorDict'>"
_META_KEYS = {"shape", "device", "_type"}


def check_plain_memmap(folder: str | Path, source: str) -> None:
    """Refuse a ``TensorDict.memmap`` folder holding anything but plain tensors (nested folders of
    them included) before ``TensorDict.load_memmap`` reads it: for other entry types it unpickles
    ``other.pickle``, which can run code."""
    folder = Path(folder)
    meta_file = folder / "meta.json"
    if not meta_file.is_file():
        raise UntrustedConfigError(f"{source}: {folder} has no meta.json (not a TensorDict memory map)")
    meta = json.loads(meta_file.read_text())
    if meta.get("_type") != _PLAIN_TYPE:
        kind = meta.get("_type")
        raise UntrustedConfigError(f"{source}: refused: {folder} holds a {kind}, not plain tensors")
    for key, entry in meta.items():
        if key in _META_KEYS:
            continue
        if not isinstance(entry, Mapping) or "dtype" not in entry or entry.get("is_nested"):
            raise UntrustedConfigError(f"{source}: refused: entry {key!r} of {folder} is not a plain tensor")
    for item in folder.iterdir():
        if item.is_dir():
            check_plain_memmap(item, source)
        elif item.name != "meta.json" and item.suffix != ".memmap":
            raise UntrustedConfigError(
                f"{source}: refused: {item.name} in {folder} is not a tensor file (it could be unpickled)"
            )
