"""Reading a trained policy: a ``.pt`` checkpoint or a policy folder, checked as received data.

Evaluation, export, deploy, DAgger's teacher and a warm start read policies; training writes them
(``rlgrasp.train.checkpoint``). The readers live here, below the training core, so that none of them
imports it. Both formats give the same in-memory dict (the layout: ``rlgrasp.train.checkpoint``).

A ``.pt`` checkpoint is a torch pickle, loaded with ``weights_only=True``: only tensors and plain
containers, so a checkpoint someone sends cannot run code when it is loaded, and one that would need
to unpickle any other object is refused (``CheckpointError``).

A policy folder holds the same policy as plain data, for readers that must not trust torch's
unpickler:

- ``model.safetensors``: the actor's state dict (the observation normalizer's ``norm.mean``,
  ``norm.var``, ``norm.count`` included), tensors under the keys ``policy_from_checkpoint`` loads;
- ``config.json``: the run's config in today's shape (``env``, ``model``, ``algo.name``), the
  checkpoint's ``spec``, its counters and evaluation, the package versions, and ``interface``: what
  each observation and action entry means (``rlgrasp.export.describe``);
- ``README.md``: a model card whose YAML block the Hugging Face Hub reads (``rlgrasp.policy_folder``
  writes all three).

Either is checked as received, by the rules of ``rlgrasp.received``: no symlink followed out of its
folder, its config read as data, its state's types and every tensor finite (``check_state``). What
is the format's stays here: a folder's tensors are checked against the model its ``config.json``
builds, so a missing, extra or misshapen tensor is one line naming it.
"""

from __future__ import annotations

import logging
import os
import pickle
import re
import sys
import zipfile
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import torch
from omegaconf import OmegaConf
from tensordict.nn import TensorDictModuleBase

from rlgrasp.config import CONFIG_DIR
from rlgrasp.models.cnn import build_vision_actor
from rlgrasp.models.mlp import OBS_KEY, RunningNorm, build_actor
from rlgrasp.received import FOLDER_CONFIG as CONFIG
from rlgrasp.received import (
    ReceivedError,
    check_finite,
    check_inside,
    check_state,
    check_tree,
    read_config,
    read_policy_meta,
)
from rlgrasp.rundir import CHECKPOINTS

#: The newest ``.pt`` checkpoint format this rlgrasp reads (and training writes).
CHECKPOINT_FORMAT = 2
NUMBERED = re.compile(r"ckpt_(\d+)\.pt$")
log = logging.getLogger("rlgrasp.train")

WEIGHTS = "model.safetensors"
CARD = "README.md"
#: The entries of a checkpoint's state a folder keeps besides the weights, the config and the spec.
RECORDS = ("frames", "updates", "best_eval_success", "last_eval", "versions")
#: How to get the optional package a folder needs (pyproject.toml's ``policy`` extra).
INSTALL = 'pip install -e ".[policy]" (or pip install safetensors)'


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: missing, unreadable, refused; the message says which file."""


def is_policy_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a folder holding ``model.safetensors`` and ``config.json`` (links included:
    a linked file is then refused by the reader with its own message, not taken for a run directory)."""
    path = Path(path)
    return path.is_dir() and all(os.path.lexists(path / name) for name in (WEIGHTS, CONFIG))


def safetensors_torch() -> Any:
    """``safetensors.torch``, or a one-line ``ImportError`` naming the extra to install."""
    try:
        import safetensors.torch as st  # lazy: an optional dependency, for policy folders only
    except ImportError:
        raise ImportError(f"a policy folder needs the safetensors package: {INSTALL}") from None
    return st


def read_policy_folder(folder: str | os.PathLike, user: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The checkpoint dict a policy folder holds, as ``read_checkpoint`` returns a ``.pt`` file's
    (``format``, ``actor``, ``config`` read as data, ``spec``, counters, ``kind`` for a camera policy);
    ``ReceivedError`` names the file, key or tensor that is wrong and what is allowed.

    Its plain data is read as received first (``rlgrasp.received.read_policy_meta``), then its tensors
    against the model that data builds, then the whole state as a ``.pt`` file's is (``check_state``)."""
    folder = Path(folder)
    source = f"policy folder {folder}"
    try:
        safetensors_torch()
    except ImportError as exc:
        raise ReceivedError(f"{source}: {exc}") from None
    meta = read_policy_meta(folder, source, user)
    config = meta["config"]
    spec = meta["spec"]
    state: dict[str, Any] = {
        "format": CHECKPOINT_FORMAT,
        **({"kind": "vision"} if meta["kind"] == "vision" else {}),
        "config": config,
        "spec": spec,
        **{k: meta[k] for k in RECORDS if k in meta},
    }
    expected = expected_tensors(spec, config.get("model"), meta["kind"], source)
    state["actor"] = _read_tensors(folder / WEIGHTS, expected, source)
    check_state(state, source)
    return state


def expected_tensors(
    spec: Mapping[str, Any], model: Any, kind: str, source: str
) -> dict[str, tuple[list[int], torch.dtype]]:
    """Key -> (shape, dtype) of every tensor the policy of ``config.json`` holds: the state dict of
    the very module ``policy_from_checkpoint`` loads the weights into."""
    if not isinstance(model, Mapping):
        raise ReceivedError(f"{source}: refused: {CONFIG} has no config.model mapping")
    try:
        module = policy_module(spec, OmegaConf.create(dict(model)), kind == "vision")
    except Exception as exc:  # a model config of wrong values: any builder's error, in one line
        raise ReceivedError(
            f"{source}: refused: {CONFIG}'s model cannot be built ({_one_line(exc)})"
        ) from None
    return {k: (list(v.shape), v.dtype) for k, v in module.state_dict().items()}


def _read_tensors(
    path: Path, expected: Mapping[str, tuple[list[int], torch.dtype]], source: str
) -> dict[str, torch.Tensor]:
    """The tensors of ``model.safetensors``, their names, shapes and dtypes checked against
    ``expected`` from the file's header before any tensor is read."""
    from safetensors import SafetensorError, safe_open

    if not path.is_file():
        raise ReceivedError(f"{source}: {WEIGHTS} is missing")
    unreadable = (SafetensorError, OSError, ValueError, RuntimeError)
    try:
        with safe_open(str(path), framework="pt") as f:
            found = {k: (list(f.get_slice(k).get_shape()), f.get_slice(k).get_dtype()) for k in f.keys()}
    except unreadable as exc:
        raise ReceivedError(f"{source}: unreadable {WEIGHTS} ({_one_line(exc)})") from None
    _check_header(found, expected, source)
    try:
        tensors = safetensors_torch().load_file(str(path))
    except unreadable as exc:
        raise ReceivedError(f"{source}: unreadable {WEIGHTS} ({_one_line(exc)})") from None
    for key, tensor in tensors.items():
        check_finite(tensor, f"{WEIGHTS}: {key}", source)
    return tensors


#: safetensors' dtype names (``get_dtype``) of the dtypes a policy holds.
_DTYPES = {"F32": torch.float32, "F64": torch.float64, "F16": torch.float16, "BF16": torch.bfloat16}


def _check_header(
    found: Mapping[str, tuple[list[int], str]],
    expected: Mapping[str, tuple[list[int], torch.dtype]],
    source: str,
) -> None:
    """The first tensor that is missing, extra, or of another shape or dtype, in one line."""
    for key in expected:
        if key not in found:
            raise ReceivedError(
                f"{source}: refused: {WEIGHTS} has no tensor {key!r}, which the model of {CONFIG} needs "
                f"({len(expected)} tensors)"
            )
    for key in found:
        if key not in expected:
            raise ReceivedError(
                f"{source}: refused: {WEIGHTS} holds the tensor {key!r}, which the model of {CONFIG} "
                f"does not have (it has {len(expected)}: {', '.join(list(expected)[:3])}, ...)"
            )
    for key, (shape, dtype) in expected.items():
        got_shape, got_dtype = found[key]
        if got_shape != shape:
            raise ReceivedError(
                f"{source}: refused: {WEIGHTS} tensor {key!r} has shape {got_shape}, the model of "
                f"{CONFIG} needs {shape}"
            )
        if _DTYPES.get(got_dtype) != dtype:
            raise ReceivedError(
                f"{source}: refused: {WEIGHTS} tensor {key!r} is {got_dtype}, the model of {CONFIG} "
                f"needs {str(dtype).removeprefix('torch.')}"
            )


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:200]


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
    if isinstance(state.get("format"), int) and state["format"] > CHECKPOINT_FORMAT:
        raise CheckpointError(
            f"checkpoint of a newer rlgrasp: {path} has format {state['format']}, this version reads up to "
            f"format {CHECKPOINT_FORMAT} (upgrade rlgrasp)"
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
    """A policy folder's checkpoint dict (above), checked as a file's is."""
    try:
        state = read_policy_folder(path, user)
    except ReceivedError as exc:
        raise CheckpointError(str(exc)) from None
    state["actor"] = {k: v.to(map_location) for k, v in state["actor"].items()}
    return state


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
    numbered = sorted((p for p in ckpt_dir.glob("ckpt_*.pt") if NUMBERED.search(p.name)), reverse=True)
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


def policy_module(spec: Mapping[str, Any], model_cfg: Any, vision: bool) -> TensorDictModuleBase:
    """The deterministic policy a checkpoint's ``spec`` and model config describe, with fresh weights:
    what its ``actor`` state dict is loaded into, and what a policy folder's tensors are checked
    against (above), so both readers expect the same keys and shapes."""
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
