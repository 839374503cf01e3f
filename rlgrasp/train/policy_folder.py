"""A policy folder: a trained policy others read without unpickling anything.

A ``.pt`` checkpoint is a torch pickle: rlgrasp loads it with ``weights_only=True``, but any other
reader must trust torch's unpickler. A policy folder holds the same policy as plain data:

- ``model.safetensors``: the actor's state dict (the observation normalizer's ``norm.mean``,
  ``norm.var``, ``norm.count`` included), tensors under the keys ``policy_from_checkpoint`` loads;
- ``config.json``: the run's config in today's shape (``env``, ``model``, ``algo.name``), the
  checkpoint's ``spec``, its counters and evaluation, the package versions, and ``interface``: what
  each observation and action entry means (``rlgrasp.export.describe``);
- ``README.md``: a model card whose YAML block the Hugging Face Hub reads (``rlgrasp.policy_folder``).

``read_policy_folder`` turns one into the in-memory checkpoint a ``.pt`` file gives
(``rlgrasp.train.checkpoint.read_checkpoint``), checked as a received folder (``rlgrasp.received``):
no symlink in it, its config read as data, and every tensor checked against the model its
``config.json`` builds, so a missing, extra or misshapen tensor is one line naming it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from omegaconf import OmegaConf

from rlgrasp.received import ReceivedError, check_finite, check_tree, read_config

WEIGHTS = "model.safetensors"
CONFIG = "config.json"
CARD = "README.md"
#: ``config.json``'s ``format``, and the newest ``format_version`` this rlgrasp reads.
FORMAT = "rlgrasp-policy"
FORMAT_VERSION = 1
KINDS = ("state", "vision")
#: The entries of a checkpoint's state a folder keeps besides the weights, the config and the spec.
RECORDS = ("frames", "updates", "best_eval_success", "last_eval", "versions")
#: How to get the optional package a folder needs (pyproject.toml's ``policy`` extra).
INSTALL = 'pip install -e ".[policy]" (or pip install safetensors)'
#: A config.json larger than this is no policy's (the shipped ones are a few kB).
_MAX_CONFIG_BYTES = 4 << 20


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
    ``ReceivedError`` names the file, key or tensor that is wrong and what is allowed."""
    folder = Path(folder)
    source = f"policy folder {folder}"
    try:
        safetensors_torch()
    except ImportError as exc:
        raise ReceivedError(f"{source}: {exc}") from None
    check_tree(folder, source)  # no link anywhere in it: nothing read outside the folder
    meta = _read_json(folder / CONFIG, source)
    config = read_config(meta["config"], f"{source}: {CONFIG}", user)
    spec = meta["spec"]
    state: dict[str, Any] = {
        "format": 2,
        **({"kind": "vision"} if meta["kind"] == "vision" else {}),
        "config": config,
        "spec": spec,
        **{k: meta[k] for k in RECORDS if k in meta},
    }
    expected = expected_tensors(spec, config.get("model"), meta["kind"], source)
    state["actor"] = _read_tensors(folder / WEIGHTS, expected, source)
    return state


def _read_json(path: Path, source: str) -> dict[str, Any]:
    """``config.json`` as plain data: a mapping of this format, no NaN, with the keys a reader needs."""
    if not path.is_file():
        raise ReceivedError(f"{source}: {CONFIG} is missing")
    if path.stat().st_size > _MAX_CONFIG_BYTES:
        raise ReceivedError(f"{source}: refused: {CONFIG} is larger than {_MAX_CONFIG_BYTES:,} bytes")

    def no_constant(name: str) -> Any:
        raise ValueError(f"{name} is not a JSON number")

    try:
        meta = json.loads(path.read_text(encoding="utf-8"), parse_constant=no_constant)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ReceivedError(f"{source}: unreadable {CONFIG} ({_one_line(exc)})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise ReceivedError(f"{source}: refused: {CONFIG} has format {got!r}, not {FORMAT!r}")
    version = meta.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= FORMAT_VERSION:
        raise ReceivedError(
            f"{source}: refused: {CONFIG} has format_version {version!r}; this rlgrasp reads 1 to "
            f"{FORMAT_VERSION} (a newer one: upgrade rlgrasp)"
        )
    for key, kind in (("config", dict), ("spec", dict), ("kind", str)):
        if not isinstance(meta.get(key), kind):
            raise ReceivedError(f"{source}: refused: {CONFIG} has no {key} {kind.__name__}")
    if meta["kind"] not in KINDS:
        raise ReceivedError(f"{source}: refused: {CONFIG} kind={meta['kind']!r}: must be one of {KINDS}")
    from rlgrasp.train.checkpoint import check_spec  # lazy: checkpoint imports this module

    check_spec(meta["spec"], f"{source}: {CONFIG}")
    for key in ("obs_dim", "action_dim", "action_low", "action_high"):
        if key not in meta["spec"]:
            raise ReceivedError(f"{source}: refused: {CONFIG} has no spec.{key}")
    return meta


def expected_tensors(
    spec: Mapping[str, Any], model: Any, kind: str, source: str
) -> dict[str, tuple[list[int], torch.dtype]]:
    """Key -> (shape, dtype) of every tensor the policy of ``config.json`` holds: the state dict of
    the very module ``policy_from_checkpoint`` loads the weights into."""
    from rlgrasp.train.checkpoint import policy_module  # lazy: checkpoint imports this module

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
