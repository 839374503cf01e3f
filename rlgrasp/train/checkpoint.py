"""Checkpoints: atomic save/load, retention, and rebuilding a deterministic policy from one file.

Layout of a checkpoint (a plain dict, ``torch.save``d; ``rlgrasp.train.loop.Trainer.state_dict``
writes it, for every algorithm):

- ``format``: 2 (1: RNG states as numpy/python objects, not loadable with ``weights_only=True``)
- ``actor``: the policy's state dict (it includes the observation normalizer's buffers
  ``norm.mean``/``norm.var``/``norm.count``); every algorithm's, so evaluation and export read any
- ``<algo.name>``: what the algorithm adds (``rlgrasp.train.algorithm.Algorithm.state_dict``) under
  its own key: ``ppo``: ``critic``, ``optimizer`` (Adam's state) and each term with weights (``rnd``);
  ``sac`` (a subclass's under its own name): its loss's critics, target critics and temperature, the
  optimizers, the gradient steps owed (the replay buffer is in the run directory's ``replay/``,
  ``rlgrasp.algos.sac.replay_files``); ``distill``: ``student``, ``aux``, ``optimizer``. Checkpoints
  written before kept PPO's and DAgger's at the top level (``rlgrasp.train.legacy.algorithm_state``)
- ``frames``, ``updates``: counters; ``generation``: how many times the run was resumed
- ``best_eval_success``, ``last_eval``: evaluation bookkeeping (``last_eval`` may be None)
- ``rng``: python / numpy / torch RNG states of the learner, as tensors and plain values
- ``config``: the resolved training config as a plain dict (``config["env"]`` is the env's
  ``_target_`` node, which ``rlgrasp.envs.factory.env_factory`` builds); an older checkpoint's is
  read in today's shape (``rlgrasp.train.legacy``)
- ``spec``: ``obs_key``, ``obs_dim``, ``action_dim``, ``action_low``, ``action_high``
- ``versions``: python, torch, torchrl, tensordict, gymnasium, pybullet, rlgrasp
- ``run_dir``: the run directory it was written in
- a demonstration file is referenced by ``config["algo"]["demos"]``, not stored

Only tensors and plain containers are stored, and every reader loads with ``weights_only=True``: a
checkpoint someone sends cannot run code when it is loaded, and one that would need to unpickle any
other object is refused (``CheckpointError``).

Every reader here also takes a policy folder (``model.safetensors`` + ``config.json``,
``rlgrasp.train.policy_folder``) where it takes a file: the same dict, with nothing unpickled at all.
"""

from __future__ import annotations

import logging
import math
import os
import pickle
import random
import re
import sys
import zipfile
from collections.abc import Iterator, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import OmegaConf
from tensordict.nn import TensorDictModuleBase

from rlgrasp.config import CONFIG_DIR
from rlgrasp.models.cnn import build_vision_actor
from rlgrasp.models.mlp import OBS_KEY, RunningNorm, build_actor
from rlgrasp.received import ReceivedError, check_finite, check_inside, check_tree, read_config
from rlgrasp.rundir import CHECKPOINTS
from rlgrasp.train.policy_folder import CONFIG, WEIGHTS, is_policy_folder, read_policy_folder

FORMAT = 2
_NUMBERED = re.compile(r"ckpt_(\d+)\.pt$")
log = logging.getLogger("rlgrasp.train")


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: missing, unreadable, refused; the message says which file."""


def save_checkpoint(path: str | os.PathLike, state: dict[str, Any]) -> Path:
    """Write ``state`` to ``path`` atomically and durably: a crash mid-write never leaves a broken
    file, a failed write (a full disk) leaves no temporary file, and the file and its directory entry
    are on disk before this returns (a power loss after it cannot lose the checkpoint)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            torch.save(state, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)
    return path


def _fsync_dir(folder: Path) -> None:
    """The rename itself on disk (POSIX; a no-op where directories cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def read_checkpoint(
    path: str | os.PathLike, map_location: str | torch.device = "cpu", user: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Load one checkpoint file with ``weights_only=True`` and read its config as data
    (``rlgrasp.received.read_config``; ``user``: the user's own config, whose classes the file may
    name at the same nodes); ``CheckpointError`` says in one line what is wrong."""
    path = Path(path)
    if is_policy_folder(path):
        return _read_folder(path, map_location, user)
    if path.is_dir():
        raise CheckpointError(
            f"missing checkpoint: {path} is a folder without {WEIGHTS} and {CONFIG} (not a policy folder)"
        )
    if not path.is_file():
        raise CheckpointError(f"missing checkpoint: {path} does not exist")
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        if "Unsupported global" not in str(exc):  # garbage, or a pickle that is no checkpoint
            raise CheckpointError(f"unreadable checkpoint: {path} ({unpickler_reason(exc)})") from exc
        raise CheckpointError(
            f"refused checkpoint: {path} needs to unpickle arbitrary Python objects "
            f"({unpickler_reason(exc)}); only tensors and plain "
            "containers are loaded (an rlgrasp checkpoint of format >= 2 holds nothing else)"
        ) from exc
    except (RuntimeError, EOFError, zipfile.BadZipFile, ValueError, OSError, AttributeError) as exc:
        raise CheckpointError(
            f"unreadable checkpoint: {path} ({type(exc).__name__}: {_first_line(exc)})"
        ) from exc
    if not isinstance(state, dict) or "actor" not in state or "config" not in state:
        held = state if isinstance(state, dict) else {}
        missing = ", ".join(k for k in ("actor", "config", "spec") if k not in held)
        raise CheckpointError(f"not an rlgrasp training checkpoint: {path} (missing {missing})")
    if isinstance(state.get("format"), int) and state["format"] > FORMAT:
        raise CheckpointError(
            f"checkpoint of a newer rlgrasp: {path} has format {state['format']}, this version reads up to "
            f"format {FORMAT} (upgrade rlgrasp)"
        )
    try:  # data until read: its config is rebuilt by rlgrasp's own code (rlgrasp.received)
        state["config"] = read_config(state["config"], str(path), user)
        check_state(state, str(path))
    except ReceivedError as exc:
        raise CheckpointError(str(exc)) from None
    return state


def _read_folder(
    path: Path, map_location: str | torch.device, user: Mapping[str, Any] | None
) -> dict[str, Any]:
    """A policy folder's checkpoint dict (``rlgrasp.train.policy_folder``), checked as a file's is."""
    try:
        state = read_policy_folder(path, user)
        check_state(state, f"policy folder {path}")
    except ReceivedError as exc:
        raise CheckpointError(str(exc)) from None
    state["actor"] = {k: v.to(map_location) for k, v in state["actor"].items()}
    return state


#: The counters a checkpoint may hold, each a whole number.
_COUNTERS = ("format", "frames", "updates", "generation")


def check_state(state: dict[str, Any], source: str) -> None:
    """The parts of a checkpoint that readers index into, in the types they expect, and every
    floating tensor finite (a diverged run's NaN weights would fail in the first step of a worker)."""
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
    for key, tensor in _tensors(state, ""):
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
        values = value.tolist() if isinstance(value, torch.Tensor) else value
        numbers = isinstance(values, list) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values
        )
        if not numbers or len(values) != spec.get("action_dim", len(values)):
            raise ReceivedError(
                f"{source}: refused: spec.{key} holds not {spec.get('action_dim')} finite numbers"
            )


def _tensors(node: Any, path: str) -> Iterator[tuple[str, torch.Tensor]]:
    if isinstance(node, torch.Tensor):
        yield path, node
    elif isinstance(node, Mapping):
        for key, value in node.items():
            yield from _tensors(value, f"{path}.{key}" if path else str(key))
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            yield from _tensors(value, f"{path}[{i}]")


def unpickler_reason(exc: BaseException) -> str:
    """What torch's weights-only unpickler refused, in one line."""
    text = str(exc)
    if "WeightsUnpickler error:" in text:
        text = text.split("WeightsUnpickler error:", 1)[1].split("Check the documentation", 1)[0]
    return " ".join(text.split())[:200] or type(exc).__name__


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0][:300]


def checkpoint_files(ckpt_dir: str | os.PathLike) -> list[Path]:
    """A run's checkpoints, newest first: ``last.pt``, then ``ckpt_<frames>.pt`` by frames."""
    ckpt_dir = Path(ckpt_dir)
    numbered = sorted((p for p in ckpt_dir.glob("ckpt_*.pt") if _NUMBERED.search(p.name)), reverse=True)
    last = ckpt_dir / "last.pt"
    return ([last] if last.is_file() else []) + numbered


def newest_readable(
    run_dir: str | os.PathLike,
    map_location: str | torch.device = "cpu",
    user: Mapping[str, Any] | None = None,
) -> tuple[Path, dict[str, Any]]:
    """``(path, state)`` of the newest checkpoint of a run that loads; a bad ``last.pt`` (say,
    truncated by a full disk) is skipped with a warning naming it."""
    ckpt_dir = Path(run_dir) / CHECKPOINTS
    try:  # a link would read (and a resume write) wherever it points (rlgrasp.received)
        check_inside(run_dir, ckpt_dir, f"run directory {run_dir}")
        check_tree(ckpt_dir, f"run directory {run_dir}")
    except ReceivedError as exc:
        raise CheckpointError(str(exc)) from None
    files = checkpoint_files(ckpt_dir)
    if not files:
        raise CheckpointError(f"no checkpoints: {ckpt_dir} holds no last.pt or ckpt_*.pt")
    errors = []
    for path in files:
        try:
            state = read_checkpoint(path, map_location, user)
        except CheckpointError as exc:
            errors.append(str(exc))
            log.warning("skipping %s", exc)
            continue
        if errors:
            log.warning("resuming from %s instead (the newer file(s) could not be loaded)", path)
        return path, state
    raise CheckpointError(f"no readable checkpoint in {ckpt_dir}: " + "; ".join(errors))


def resolve_policy_path(path: str) -> str:
    """A checkpoint path (a file, a policy folder, a run directory) as given, or, when relative and
    not found from the working directory, from the repository root: the experiments name the shipped
    policies ``policies/<name>.pt`` (or the folder ``policies/<name>``)."""
    candidate = Path(path).expanduser()
    if not candidate.is_absolute() and not candidate.exists():
        from_root = Path(CONFIG_DIR).parent / candidate
        if from_root.exists():
            return str(from_root)
    return str(candidate)


def load_checkpoint(
    path: str | os.PathLike, map_location: str | torch.device = "cpu", user: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Load a checkpoint file or a policy folder, or a run directory's newest readable checkpoint
    (normally ``last.pt``); ``user``: the user's own config (``read_checkpoint``)."""
    path = Path(path)
    if path.is_dir() and not is_policy_folder(path):
        return newest_readable(path, map_location, user)[1]
    return read_checkpoint(path, map_location, user)


def rng_state() -> dict[str, Any]:
    """Python, numpy and torch RNG states as tensors and plain values (``weights_only`` loadable)."""
    version, py_state, gauss = random.getstate()
    name, keys, pos, has_gauss, cached = np.random.get_state()
    return {
        "python": {"version": version, "state": torch.tensor(py_state, dtype=torch.int64), "gauss": gauss},
        "numpy": {
            "name": str(name),
            "keys": torch.from_numpy(keys.astype(np.int64)),
            "pos": int(pos),
            "has_gauss": int(has_gauss),
            "cached_gaussian": float(cached),
        },
        "torch": torch.get_rng_state(),
    }


def set_rng_state(state: dict[str, Any]) -> None:
    py, npy = state["python"], state["numpy"]
    random.setstate((py["version"], tuple(int(x) for x in py["state"].tolist()), py["gauss"]))
    keys = npy["keys"].numpy().astype(np.uint32)
    np.random.set_state((npy["name"], keys, npy["pos"], npy["has_gauss"], npy["cached_gaussian"]))
    torch.set_rng_state(state["torch"])


TRAINING_PACKAGES = ("torch", "torchrl", "tensordict", "gymnasium", "pybullet", "hydra-core", "rlgrasp")


def package_versions(
    names: tuple[str, ...] = TRAINING_PACKAGES, missing: str | None = "unknown"
) -> dict[str, str]:
    """Python's and each package's version; a package not installed is ``missing`` (None: left out)."""
    out = {"python": sys.version.split()[0]}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            if missing is not None:
                out[name] = missing
    return out


def write_checkpoints(
    ckpt_dir: str | os.PathLike, state: dict[str, Any], keep_last: int, is_best: bool
) -> Path:
    """Write ``last.pt`` first, then ``ckpt_<frames>.pt`` (and ``best.pt``), and keep the last K
    numbered ones: an interruption between the writes leaves ``last.pt`` the newest, which is what a
    resume reads first. Separate files, not links: a ``last.pt`` damaged in place leaves the
    numbered ones to resume from."""
    ckpt_dir = Path(ckpt_dir)
    save_checkpoint(ckpt_dir / "last.pt", state)
    numbered = save_checkpoint(ckpt_dir / f"ckpt_{state['frames']:010d}.pt", state)
    if is_best:
        save_checkpoint(ckpt_dir / "best.pt", state)
    olds = sorted(p for p in ckpt_dir.glob("ckpt_*.pt") if _NUMBERED.search(p.name))
    for old in olds[: max(len(olds) - max(keep_last, 1), 0)]:
        old.unlink(missing_ok=True)
    return numbered


def policy_module(spec: Mapping[str, Any], model_cfg: Any, vision: bool) -> TensorDictModuleBase:
    """The deterministic policy a checkpoint's ``spec`` and model config describe, with fresh weights:
    what its ``actor`` state dict is loaded into, and what a policy folder's tensors are checked
    against (``rlgrasp.train.policy_folder``), so both readers expect the same keys and shapes."""
    if vision:  # a camera student (rlgrasp.algos.dagger): state + images in
        return build_vision_actor(spec, model_cfg, deterministic=True)
    norm = RunningNorm(spec["obs_dim"], clip=model_cfg.obs_clip, enabled=model_cfg.obs_norm)
    return build_actor(
        norm,
        spec["obs_dim"],
        torch.as_tensor(spec["action_low"]),
        torch.as_tensor(spec["action_high"]),
        model_cfg,
        deterministic=True,
    )


def policy_from_checkpoint(
    ckpt: dict[str, Any] | str | os.PathLike, device: str | torch.device = "cpu"
) -> TensorDictModuleBase:
    """The deterministic policy (normalizer included) from a checkpoint alone.

    Reads ``ckpt["observation"]`` from a tensordict (a camera policy, ``kind == "vision"``, also its
    image entries) and writes ``"action"`` (the distribution's mode).
    Accepts a loaded dict, a checkpoint path, a policy folder or a run directory.
    """
    if not isinstance(ckpt, dict):
        ckpt = load_checkpoint(ckpt, map_location=device)
    spec = ckpt["spec"]
    model_cfg = OmegaConf.create(ckpt["config"]["model"])
    vision = ckpt.get("kind") == "vision"
    actor = policy_module(spec, model_cfg, vision)
    try:
        actor.load_state_dict(ckpt["actor"])
    except RuntimeError as exc:
        what = "model" if vision else "model config"
        raise CheckpointError(f"checkpoint does not fit its own {what}: {_first_line(exc)}") from exc
    if not vision and spec.get("obs_key", OBS_KEY) != OBS_KEY:
        raise CheckpointError(f"checkpoint observation key {spec.get('obs_key')!r}, expected {OBS_KEY!r}")
    return actor.to(device).eval()
