"""A received file is data: the one place that turns a file's config and folders into something rlgrasp
builds from its own code.

A checkpoint loads with ``weights_only=True`` and runs no code while it loads; its ``config`` is then
rebuilt with Hydra's ``instantiate`` (the env, the collector, the algorithm and its terms), which calls
whatever ``_target_`` a node names. A list of forbidden things misses the next route (an older format
upgraded into a target after the check, a class trusted at one node used at another), so a file's
config is read as data instead (``read_config``):

1. its shape: a mapping of plain values, no dotted key, no interpolation (``${...}``), no instantiate
   key (``_args_``, ``_partial_``, ...) anywhere, and ``_target_`` only at a node rlgrasp builds
   (``NODES``);
2. older formats upgraded into data: a ``gym_factory`` env, string-named backends, a flat ``algo``;
3. each built node's ``_target_`` read back into a short name of ``PARTS`` for that node's kind (a
   logger's class at ``env`` names nothing there; a class whose module moved is read by its path of
   today, ``rlgrasp.legacy.MOVED_MODULES``), or a class the user's own config names at that very node
   (``user_parts``: how a run of the user's own task or algorithm is read back);
4. the buildable config written from the registry: each ``_target_`` is ``PARTS``'s string for the
   short name (or the user's), never the file's. The logger is never taken from a file: the node
   keeps only its short name (``{"name": "tensorboard"}``) and a resumed run builds the user's.

Folders someone sends (a run directory, a demonstrations folder, a replay folder) are read, never
written: ``check_tree`` refuses any symlink inside them (a link moves a read or a write outside),
and ``read_memmap`` checks every tensor file's size against its declared shape before reading it
into memory itself (TensorDict's ``load_memmap`` opens files writable and grows them).

A policy, from a ``.pt`` file or a policy folder (``rlgrasp.policy_file`` reads the formats), is held
to the same rules here: a folder's plain data (no link, ``config.json`` of its format, the spec, the
config read as data) in one call, ``read_policy_meta``, before any tensor is read; and the state a
reader returns, whichever format it came in, in one call, ``check_state`` (types, counters, spec,
every tensor finite).

Every refusal is a ``ReceivedError`` whose message is one line. This module imports nothing of
rlgrasp's at import time but the algorithms' registry and the older layouts' map (``rlgrasp.legacy``;
strings, no torch), so every reader can use it.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from rlgrasp.algos.registry import alias_paths, class_paths
from rlgrasp.legacy import moved_target, nest_config

#: rlgrasp's own parts, by kind: the short name a file may choose -> the class rlgrasp builds it with.
#: Adding a kind or a part is one entry here (and its node path in ``NODES``).
PARTS: dict[str, dict[str, str]] = {
    # The class path rlgrasp's own env config writes (rlgrasp.envs.grasp_env.EnvConfig): a rebuilt config then
    # compares equal to the user's own on resume and is type-checked by EnvConfig.
    "env": {
        "grasp": "rlgrasp.envs.PandaGraspEnv",
        # Another package's gymnasium env (configs/env/gym.yaml): its env.id is checked by _check_gym_id.
        "gym": "rlgrasp.envs.gym_env.make_gym_env",
    },
    "task": {
        # The class paths configs/task/*.yaml write (rlgrasp.envs.tasks re-exports each).
        "lift": "rlgrasp.envs.tasks.LiftTask",
        "pick_place": "rlgrasp.envs.tasks.PickPlaceTask",
        "push": "rlgrasp.envs.tasks.PushTask",
        "stack": "rlgrasp.envs.tasks.StackTask",
    },
    "reward_term": {},  # only a user's own config names these
    "collector": {
        "process": "rlgrasp.train.collection.collectors.ProcessCollector",
        "single": "rlgrasp.train.collection.collectors.SingleCollector",
        "ray": "rlgrasp.train.collection.collectors.RayCollector",
    },
    # Each algorithm package's class (rlgrasp.algos.registry: a registry of strings, no torch).
    "algo": class_paths(),
    "algo_term": {
        "imitation": "rlgrasp.demos.bc.Imitation",
        "teacher": "rlgrasp.vision.teacher_term.TeacherImitation",
        "rnd": "rlgrasp.algos.ppo.rnd.RND",
    },
    # Read from a file only to record which one it used (never built from a file).
    "logger": {
        "tensorboard": "rlgrasp.train.tracking.logger.TensorBoardLogger",
        "none": "rlgrasp.train.tracking.logger.ConsoleLogger",
        "wandb": "rlgrasp.train.tracking.trackers.WandbLogger",
        "mlflow": "rlgrasp.train.tracking.trackers.MlflowLogger",
    },
}
#: Other spellings of a part's class that files carry (the same class under an older name; a class whose
#: whole module moved is ``rlgrasp.legacy.MOVED_MODULES``'s, applied before these).
ALIASES: dict[str, dict[str, str]] = {
    "env": {"rlgrasp.envs.GraspEnv": "grasp", "rlgrasp.envs.grasp_env.GraspEnv": "grasp"},
    "task": {
        "rlgrasp.envs.tasks.lift.LiftTask": "lift",
        "rlgrasp.envs.tasks.goal.PickPlaceTask": "pick_place",
        "rlgrasp.envs.tasks.goal.PushTask": "push",
        "rlgrasp.envs.tasks.goal.StackTask": "stack",
    },
    "algo": alias_paths(),  # e.g. DAgger's class before its package (rlgrasp.vision.distill.DAgger)
}
#: Where each kind is built, by node path (``*``: any one key). Only here may a file's ``_target_`` stand.
NODES: dict[str, str] = {
    "env": "env",
    "env.task": "task",
    "env.task.reward.terms.*": "reward_term",
    "collector": "collector",
    "algo": "algo",
    "algo.terms.*": "algo_term",
    "logger": "logger",
}
#: Hydra's keys that make a node callable or change how it is called.
INSTANTIATE_KEYS = ("_target_", "_args_", "_partial_", "_recursive_", "_convert_")
#: The modules a received ``env=gym`` config's ``env.id`` may import (``module:id``): the packages of envs
#: rlgrasp's extras install. Importing a module runs its code, so a file may not name any other (unless
#: the user's own config's env.id names the same module).
GYM_MODULES = ("panda_gym",)
#: The env factories an older checkpoint's ``gym_factory`` may name (module:name), all of them ``grasp``.
OLD_ENV_FACTORIES = {"rlgrasp.envs:PandaGraspEnv": "grasp", "rlgrasp.envs:GraspEnv": "grasp"}
_MAX_DEPTH = 32
_PLAIN = (str, int, float, bool, type(None))


class ReceivedError(ValueError):
    """A received file or folder that is refused; the message is one line and names the key or file."""


def read_config(config: Any, source: str, user: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The buildable config of a received ``config`` (a copy), or ``ReceivedError`` naming the key.

    ``user``: the user's own composed config (plain containers): a class it names at a node path is
    a part the file may name at that same path."""
    if not isinstance(config, Mapping):
        raise ReceivedError(f"{source}: refused: its config is a {type(config).__name__}, not a mapping")
    _check_plain(config, "config", source, 0)
    data, shorts = _upgrade(_copy(config), source)
    chosen = user_parts(user or {})
    for path, node in _built_nodes(data):
        kind = _node_kind(path)
        if kind == "logger":  # a record of what it used; the user's own logger is the one built
            data["logger"] = {"name": shorts.get(path) or _logger_name(node)}
        elif "_target_" in node or path in shorts:
            node["_target_"] = _class_for(kind, path, node.get("_target_"), shorts.get(path), chosen, source)
    _check_gym_id(data, user or {}, source)
    return data


def _check_gym_id(data: Mapping[str, Any], user: Mapping[str, Any], source: str) -> None:
    """An ``env=gym`` config's ``env.id`` may import only a module of ``GYM_MODULES`` (``panda_gym:...``)
    or the one the user's own config's ``env.id`` names: gymnasium imports the module before it looks the
    id up, and an import runs that module's code. An id without a module is looked up among the ids
    already registered, which only code the user runs has registered."""
    env = data.get("env")
    if not isinstance(env, Mapping) or env.get("_target_") != PARTS["env"]["gym"]:
        return
    env_id = env.get("id")
    if not isinstance(env_id, str):
        raise ReceivedError(f"{source}: refused: config.env.id={str(env_id)[:120]!r} is not a gymnasium id")
    module = env_id.rpartition(":")[0]
    theirs = (user.get("env") or {}).get("id") if isinstance(user.get("env"), Mapping) else None
    if module and module not in GYM_MODULES and module != str(theirs or "").rpartition(":")[0]:
        raise ReceivedError(
            f"{source}: refused: config.env.id={env_id[:120]!r} would import the module {module[:80]!r}; a "
            f"received file may name {', '.join(GYM_MODULES)} (or the module your own config's env.id names)"
        )


def user_parts(user: Mapping[str, Any]) -> dict[str, str]:
    """The class the user's own config names at each node path rlgrasp builds (``{"algo.terms.mine":
    "mypkg.Term"}``): the parts of their own that a file read beside it may name there."""
    return {path: str(node["_target_"]) for path, node in _built_nodes(user) if "_target_" in node}


def logger_name(config: Mapping[str, Any]) -> str | None:
    """The short name of the logger a config builds (``tensorboard``), ``None`` without one."""
    node = config.get("logger")
    if not isinstance(node, Mapping):
        return None
    return node.get("name") or _short_name("logger", node.get("_target_"))


def _logger_name(node: Mapping[str, Any]) -> str:
    """The short name of the logger a config's ``logger`` node used: its class's, or, in a config
    already read (a policy-only file keeps the record, ``{"name": ...}``), the record's own when it is
    one of rlgrasp's names, so that reading a read config changes nothing."""
    recorded = node.get("name")
    if "_target_" not in node and recorded in (*PARTS["logger"], "another"):
        return str(recorded)
    return _short_name("logger", node.get("_target_"))


def _short_name(kind: str, target: Any) -> str:
    return _known(kind, target) or "another"


def _copy(node: Any) -> Any:
    """A deep copy of plain containers (lists for tuples), without ``copy``'s reach into objects."""
    if isinstance(node, Mapping):
        return {k: _copy(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [_copy(v) for v in node]
    return node


def _check_plain(node: Any, where: str, source: str, depth: int) -> None:
    """Refuse anything but plain values, string keys without dots, no interpolation, and no
    instantiate key but a ``_target_`` at a node rlgrasp builds."""
    if depth > _MAX_DEPTH:
        raise ReceivedError(f"{source}: refused: {where} is nested deeper than {_MAX_DEPTH} levels")
    if isinstance(node, Mapping):
        for key, value in node.items():
            if not isinstance(key, str):
                raise ReceivedError(f"{source}: refused: {where} has the key {key!r}; keys are strings")
            here = f"{where}.{key}"
            if "." in key or "${" in key:
                raise ReceivedError(
                    f"{source}: refused: {where} has the key {key!r}; a saved config nests its keys"
                )
            if key in INSTANTIATE_KEYS and not (key == "_target_" and _node_kind(where) is not None):
                raise ReceivedError(
                    f"{source}: refused: {here} would be called when the config is built (a file may "
                    f"choose a part only at {', '.join('config.' + n for n in NODES)}, by its short name)"
                )
            _check_plain(value, here, source, depth + 1)
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            _check_plain(value, f"{where}[{i}]", source, depth + 1)
    elif not isinstance(node, _PLAIN):
        kind = type(node).__name__
        raise ReceivedError(f"{source}: refused: {where} is a {kind}; a config holds plain values")
    elif isinstance(node, str) and "${" in node:
        raise ReceivedError(
            f"{source}: refused: {where} holds an interpolation (${{...}}); a saved config is stored "
            "resolved, and nothing of a received file is resolved"
        )
    elif node == "???":
        raise ReceivedError(f"{source}: refused: {where} is '???' (a missing value); a saved one has values")


def _node_kind(where: str) -> str | None:
    """The kind built at ``where`` (``config.algo.terms.rnd`` -> ``algo_term``), None for other nodes."""
    parts = where.split(".")[1:] if where.startswith("config") else where.split(".")
    for pattern, kind in NODES.items():
        want = pattern.split(".")
        if len(want) == len(parts) and all(w in ("*", p) for w, p in zip(want, parts)):
            return kind
    return None


def _built_nodes(config: Mapping[str, Any]) -> Iterator[tuple[str, dict[str, Any]]]:
    """``(path, node)`` of each node present that rlgrasp builds, parents before children."""
    for pattern in sorted(NODES, key=lambda p: p.count(".")):
        yield from _matching(config, pattern.split("."), "")


def _matching(node: Any, want: list[str], path: str) -> Iterator[tuple[str, Any]]:
    if not want:
        if isinstance(node, Mapping):
            yield path, node
        return
    if not isinstance(node, Mapping):
        return
    keys = list(node) if want[0] == "*" else [want[0]] if want[0] in node else []
    for key in keys:
        yield from _matching(node[key], want[1:], f"{path}.{key}" if path else key)


def _class_for(
    kind: str, path: str, target: Any, short: str | None, chosen: Mapping[str, str], source: str
) -> str:
    """The class rlgrasp builds the node at ``path`` with: the registry's for the short name its
    ``_target_`` (or its older format, ``short``) reads back to, or the class the user's own config
    names at ``path``; never the file's string."""
    if target is not None and target == chosen.get(path):
        return chosen[path]  # the user's own part, named by the user's own config at this node
    name = short if target is None else _known(kind, target)
    if name is None:
        allowed = ", ".join(f"{n} ({c})" for n, c in PARTS[kind].items()) or "none of rlgrasp's"
        raise ReceivedError(
            f"{source}: refused: config.{path}._target_={str(target)[:120]!r} is not a part rlgrasp builds "
            f"at {path} (a {kind}: {allowed}; a class of your own: name it at {path}._target_ in your "
            "own config)"
        )
    return PARTS[kind][name]


def _known(kind: str, target: Any) -> str | None:
    """The short name of ``PARTS[kind]`` that ``target`` names (by today's path, an alias, or the path
    of before its module moved), None for any other."""
    if not isinstance(target, str):
        return None
    target = moved_target(target)
    for name, cls in PARTS[kind].items():
        if cls == target:
            return name
    return ALIASES.get(kind, {}).get(target)


def _upgrade(config: dict[str, Any], source: str) -> tuple[dict[str, Any], dict[str, str]]:
    """Older formats in today's shape, as data: the config, and the short name each old way of naming
    a part stands for, by node path (turned into the registry's class by ``_class_for``). An old name
    that is not one of rlgrasp's parts is refused, never turned into a class."""
    for key in ("env", "collector", "algo", "logger"):
        if (
            key in config
            and not isinstance(config[key], Mapping)
            and (key != "logger" or config[key] is not None)
        ):
            raise ReceivedError(
                f"{source}: refused: config.{key} is a {type(config[key]).__name__}, not a mapping"
            )
    shorts: dict[str, str] = {}
    if isinstance(config.get("env"), dict) and "_target_" not in config["env"]:
        config["env"], shorts["env"] = _old_env(config["env"], source)
    collector = config.get("collector")
    if isinstance(collector, dict) and "backend" in collector and "_target_" not in collector:
        backend = collector.pop("backend")
        if backend not in PARTS["collector"]:
            raise ReceivedError(
                f"{source}: refused: config.collector.backend={str(backend)[:120]!r} is not a collector "
                f"rlgrasp builds (allowed: {', '.join(PARTS['collector'])})"
            )
        if backend != "ray":
            collector.pop("ray", None)
        shorts["collector"] = backend
    logger = config.get("logger")
    if isinstance(logger, dict) and "backend" in logger and "_target_" not in logger:
        tracker = logger.get("tracker")
        name = tracker if tracker in ("wandb", "mlflow") else logger["backend"]
        shorts["logger"] = name if name in PARTS["logger"] else "another"
    # The env's and a flat algo's keys nested by role; the terms an algorithm builds by class get its
    # schema's class (rlgrasp.legacy), which _class_for then reads back into the registry's.
    config = nest_config(config)
    if isinstance(config.get("algo"), dict):
        name = config["algo"].get("name")
        if "_target_" not in config["algo"] and isinstance(name, str) and name in PARTS["algo"]:
            shorts["algo"] = name  # written before algo._target_: the algorithm its name registers
    return config, shorts


def _old_env(env: dict[str, Any], source: str) -> tuple[dict[str, Any], str]:
    """An env node of before it was a ``_target_`` node: ``gym_factory`` named the env (module:name),
    ``kwargs`` held further keywords and ``factory`` the TorchRL wrapper."""
    factory = env.pop("gym_factory", "rlgrasp.envs:PandaGraspEnv")
    if factory not in OLD_ENV_FACTORIES:
        raise ReceivedError(
            f"{source}: refused: config.env.gym_factory={str(factory)[:120]!r} is not an env rlgrasp builds "
            f"(allowed: {', '.join(OLD_ENV_FACTORIES)})"
        )
    env.pop("factory", None)
    extra = env.pop("kwargs", None) or {}
    if not isinstance(extra, Mapping):
        kind = type(extra).__name__
        raise ReceivedError(f"{source}: refused: config.env.kwargs is a {kind}, not a mapping")
    return {**env, **extra}, OLD_ENV_FACTORIES[factory]


# --- folders ------------------------------------------------------------------------------------


def check_tree(root: str | os.PathLike, source: str) -> None:
    """Refuse ``root`` when it, or anything inside it, is a symlink: a received folder is read where
    it lies, and a link would move a read, a write or a removal to wherever it points."""
    root = Path(root)
    if root.is_symlink():
        raise ReceivedError(
            f"{source}: refused: {root} is a symlink (to {os.readlink(root)}); give the folder"
        )
    if not root.is_dir():
        return
    for folder, dirs, files in os.walk(root, followlinks=False):
        for name in (*dirs, *files):
            item = Path(folder) / name
            if item.is_symlink():
                raise ReceivedError(
                    f"{source}: refused: {item} is a symlink (to {os.readlink(item)}); a received folder "
                    "is read where it lies, never through a link"
                )


def check_inside(root: str | os.PathLike, path: str | os.PathLike, source: str) -> None:
    """Refuse ``path`` unless it lies inside ``root`` with no symlink on the way (``root`` included)."""
    root, path = Path(os.path.abspath(root)), Path(os.path.abspath(path))
    try:
        rest = path.relative_to(root)
    except ValueError:
        raise ReceivedError(f"{source}: refused: {path} is not inside {root}") from None
    here = root
    for part in ("", *rest.parts):
        here = here / part if part else here
        if here.is_symlink():
            raise ReceivedError(
                f"{source}: refused: {here} is a symlink (to {os.readlink(here)}); nothing of a received "
                "folder is followed through a link"
            )


# --- a policy folder's plain data (its tensors are rlgrasp.policy_file's) -----------------------

#: A policy folder's description, its ``format``, the newest ``format_version`` this rlgrasp reads,
#: and the kinds of policy it holds (the layout: ``rlgrasp.policy_file``).
FOLDER_CONFIG = "config.json"
FOLDER_FORMAT = "rlgrasp-policy"
FORMAT_VERSION = 1
FOLDER_KINDS = ("state", "vision")
#: A config.json larger than this is no policy's (the shipped ones are a few kB).
_MAX_CONFIG_BYTES = 4 << 20


def read_policy_meta(
    folder: str | os.PathLike, source: str, user: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """A policy folder's ``config.json`` as plain data, in one call before any tensor is read: the
    folder holds no link, the file is a mapping of this format with a valid ``spec``, and its
    ``config`` is read as data (``read_config``; ``user`` as there)."""
    folder = Path(folder)
    check_tree(folder, source)  # no link anywhere in it: nothing read outside the folder
    meta = _read_json(folder / FOLDER_CONFIG, source)
    _check_policy_meta(meta, source)
    meta["config"] = read_config(meta["config"], f"{source}: {FOLDER_CONFIG}", user)
    return meta


def _read_json(path: Path, source: str) -> Any:
    """A received JSON file, bounded in size, as Python's values; NaN and Infinity (which Python's
    writer emits, and JSON has not) refused."""
    name = path.name
    if not path.is_file():
        raise ReceivedError(f"{source}: {name} is missing")
    if path.stat().st_size > _MAX_CONFIG_BYTES:
        raise ReceivedError(f"{source}: refused: {name} is larger than {_MAX_CONFIG_BYTES:,} bytes")

    def no_constant(constant: str) -> Any:
        raise ValueError(f"{constant} is not a JSON number")

    try:
        return json.loads(path.read_text(encoding="utf-8"), parse_constant=no_constant)
    except (ValueError, UnicodeDecodeError) as exc:
        reason = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise ReceivedError(f"{source}: unreadable {name} ({reason})") from None


def _check_policy_meta(meta: Any, source: str) -> None:
    """``config.json`` of this format and version, with the keys a reader needs."""
    if not isinstance(meta, dict) or meta.get("format") != FOLDER_FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise ReceivedError(f"{source}: refused: {FOLDER_CONFIG} has format {got!r}, not {FOLDER_FORMAT!r}")
    version = meta.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= FORMAT_VERSION:
        raise ReceivedError(
            f"{source}: refused: {FOLDER_CONFIG} has format_version {version!r}; this rlgrasp reads 1 to "
            f"{FORMAT_VERSION} (a newer one: upgrade rlgrasp)"
        )
    for key, kind in (("config", dict), ("spec", dict), ("kind", str)):
        if not isinstance(meta.get(key), kind):
            raise ReceivedError(f"{source}: refused: {FOLDER_CONFIG} has no {key} {kind.__name__}")
    if meta["kind"] not in FOLDER_KINDS:
        raise ReceivedError(
            f"{source}: refused: {FOLDER_CONFIG} kind={meta['kind']!r}: must be one of {FOLDER_KINDS}"
        )
    check_spec(meta["spec"], f"{source}: {FOLDER_CONFIG}")
    for key in ("obs_dim", "action_dim", "action_low", "action_high"):
        if key not in meta["spec"]:
            raise ReceivedError(f"{source}: refused: {FOLDER_CONFIG} has no spec.{key}")


#: What ``TensorDict.memmap`` writes for a TensorDict of plain tensors.
_PLAIN_TYPE = "<class 'tensordict._td.TensorDict'>"
_META_KEYS = {"shape", "device", "_type"}


def memmap_entries(folder: str | os.PathLike, source: str) -> dict[str, tuple[Path, str, list[int]]]:
    """``key -> (file, dtype, shape)`` of a ``TensorDict.memmap`` folder of plain tensors (nested
    folders' keys joined with ``/``), each file's size checked against its shape and dtype; refused in
    one line otherwise. Nothing is opened but ``meta.json``."""
    folder = Path(folder)
    check_tree(folder, source)
    meta = _memmap_meta(folder, source)
    found: dict[str, tuple[Path, str, list[int]]] = {}
    for item in sorted(folder.iterdir()):
        if item.is_dir():
            inner = memmap_entries(item, source)
            found.update({f"{item.name}/{k}": v for k, v in inner.items()})
        elif item.name != "meta.json" and item.suffix != ".memmap":
            raise ReceivedError(
                f"{source}: refused: {item.name} in {folder} is not a tensor file (it could be unpickled)"
            )
    for key, entry in meta.items():
        if key in _META_KEYS or (folder / key).is_dir():
            continue
        found[key] = _checked_entry(folder, key, entry, source)
    return found


def _memmap_meta(folder: Path, source: str) -> dict[str, Any]:
    meta_file = folder / "meta.json"
    if not meta_file.is_file():
        raise ReceivedError(f"{source}: {folder} has no meta.json (not a TensorDict memory map)")
    try:
        meta = json.loads(meta_file.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ReceivedError(f"{source}: unreadable {meta_file} ({type(exc).__name__})") from None
    if not isinstance(meta, dict) or meta.get("_type") != _PLAIN_TYPE:
        kind = meta.get("_type") if isinstance(meta, dict) else type(meta).__name__
        raise ReceivedError(f"{source}: refused: {folder} holds a {kind}, not plain tensors")
    return meta


def _checked_entry(folder: Path, key: str, entry: Any, source: str) -> tuple[Path, str, list[int]]:
    """One entry's file, dtype and shape, its size on disk equal to what the shape and dtype need."""
    if not isinstance(entry, Mapping) or "dtype" not in entry or entry.get("is_nested"):
        raise ReceivedError(f"{source}: refused: entry {key!r} of {folder} is not a plain tensor")
    dtype, shape = entry.get("dtype"), entry.get("shape")
    size = DTYPE_BYTES.get(dtype) if isinstance(dtype, str) else None
    if size is None:
        raise ReceivedError(f"{source}: refused: entry {key!r} of {folder} has the dtype {dtype!r}")
    if not isinstance(shape, list) or not all(isinstance(n, int) and n >= 0 for n in shape):
        raise ReceivedError(f"{source}: refused: entry {key!r} of {folder} has the shape {shape!r}")
    path = folder / f"{key}.memmap"
    if not path.is_file():
        raise ReceivedError(f"{source}: {key}.memmap is missing from {folder}")
    need, have = math.prod(shape) * size, path.stat().st_size
    if have != need:
        raise ReceivedError(
            f"{source}: refused: {path.name} in {folder} holds {have:,} bytes, its declared shape "
            f"{shape} of {dtype} needs {need:,} (cut short, or not what meta.json says)"
        )
    return path, dtype, shape


#: Bytes per element of each dtype a memory map may hold.
DTYPE_BYTES: dict[str, int] = {
    "torch.float32": 4,
    "torch.float64": 8,
    "torch.float16": 2,
    "torch.bfloat16": 2,
    "torch.uint8": 1,
    "torch.int8": 1,
    "torch.int16": 2,
    "torch.int32": 4,
    "torch.int64": 8,
    "torch.bool": 1,
}


def read_memmap(folder: str | os.PathLike, source: str) -> Any:
    """A ``TensorDict`` of the tensors in a received ``TensorDict.memmap`` folder, read into memory,
    each checked finite; the folder is only read.

    Hand-written rather than ``TensorDict.load_memmap``: that opens every file writable and resizes it
    to the shape ``meta.json`` declares (following symlinks), so a received folder could grow or zero
    a file anywhere; here each file is opened read-only, after its size was checked."""
    import torch  # lazy: this module stays light for the readers that need no tensors
    from tensordict import TensorDict

    folder = Path(folder)
    entries = memmap_entries(folder, source)
    meta = _memmap_meta(folder, source)
    tensors = {}
    for key, (path, dtype, shape) in entries.items():
        kind = getattr(torch, dtype.removeprefix("torch."))
        with open(path, "rb") as f:  # read-only, and its size already checked
            raw = bytearray(f.read())
        tensor = torch.frombuffer(raw, dtype=kind).reshape(shape) if raw else torch.empty(shape, dtype=kind)
        check_finite(tensor, key, source)
        tensors[tuple(key.split("/"))] = tensor
    batch = meta.get("shape")
    try:
        out = TensorDict({}, batch_size=batch)
        for key, tensor in tensors.items():
            out[key] = tensor
    except (RuntimeError, ValueError, TypeError) as exc:
        raise ReceivedError(f"{source}: refused: {folder}: {str(exc).splitlines()[0][:200]}") from None
    return out


def check_finite(tensor: Any, key: str, source: str) -> None:
    """Refuse a floating tensor holding NaN or inf, naming its key."""
    if tensor.is_floating_point() and tensor.numel() and not bool(tensor.isfinite().all()):
        bad = int((~tensor.isfinite()).sum())
        raise ReceivedError(f"{source}: refused: {key} holds {bad:,} NaN or infinite value(s)")


# --- a checkpoint's state -----------------------------------------------------------------------

#: The counters a checkpoint may hold, each a whole number.
_COUNTERS = ("format", "frames", "updates", "generation")


def check_state(state: dict[str, Any], source: str) -> None:
    """The parts of a checkpoint (a ``.pt`` file's or a policy folder's, its config already read by
    ``read_config``) that readers index into, in the types they expect, and every floating tensor
    finite (a diverged run's NaN weights would fail in the first step of a worker): the one check a
    reader makes of a state, whichever format it came in."""
    import torch  # lazy: this module stays light for the readers that need no tensors

    if not isinstance(state["actor"], Mapping) or not all(
        isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state["actor"].items()
    ):
        raise ReceivedError(f"{source}: refused: its actor is not a mapping of names to tensors")
    if not isinstance(state["config"].get("env"), Mapping):  # every reader builds or compares the env
        env = state["config"].get("env")
        raise ReceivedError(f"{source}: refused: config.env is {env!r:.40}, not the env's mapping")
    for key in _COUNTERS:
        value = state.get(key, 0)
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise ReceivedError(f"{source}: refused: {key}={state[key]!r} is not a whole number >= 0")
    spec = state.get("spec")
    if spec is not None:
        check_spec(spec, source)
    for key, tensor in _tensors(state, "", torch.Tensor):
        if not key.startswith("rng"):
            check_finite(tensor, key, source)


def check_spec(spec: Any, source: str) -> None:
    """``spec``'s sizes are whole numbers and its bounds one number per action."""
    if not isinstance(spec, Mapping):
        raise ReceivedError(f"{source}: refused: spec is a {type(spec).__name__}, not a mapping")
    for key in ("obs_dim", "action_dim"):
        value = spec.get(key)
        if key in spec and (not isinstance(value, int) or isinstance(value, bool) or value < 1):
            raise ReceivedError(f"{source}: refused: spec.{key}={value!r} is not a whole number >= 1")
    for key in ("action_low", "action_high"):
        if key not in spec:
            continue
        value = spec[key]
        values = value.tolist() if _is_tensor(value) else value
        numbers = isinstance(values, list) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values
        )
        if not numbers or len(values) != spec.get("action_dim", len(values)):
            raise ReceivedError(
                f"{source}: refused: spec.{key} holds not {spec.get('action_dim')} finite numbers"
            )


def _is_tensor(value: Any) -> bool:
    import torch  # lazy, as above

    return isinstance(value, torch.Tensor)


def _tensors(node: Any, path: str, tensor: type) -> Iterator[tuple[str, Any]]:
    """``(path, tensor)`` of every ``tensor`` in plain containers (``actor.mlp.0.weight``)."""
    if isinstance(node, tensor):
        yield path, node
    elif isinstance(node, Mapping):
        for key, value in node.items():
            yield from _tensors(value, f"{path}.{key}" if path else str(key), tensor)
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            yield from _tensors(value, f"{path}[{i}]", tensor)
