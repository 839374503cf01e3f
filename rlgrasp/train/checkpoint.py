"""Checkpoints: atomic save/load, retention, and rebuilding a deterministic policy from one file.

Layout of a checkpoint (a plain dict, ``torch.save``d; ``rlgrasp.train.loop.Trainer.state_dict``
writes it):

- ``format``: 1
- ``actor``, ``critic``: state dicts (both include the observation normalizer's buffers
  ``norm.mean``/``norm.var``/``norm.count``)
- ``optimizer``: Adam's state dict
- ``frames``, ``updates``: counters; ``generation``: how many times the run was resumed
- ``best_eval_success``, ``last_eval``: evaluation bookkeeping (``last_eval`` may be None)
- ``rng``: python / numpy / torch RNG states of the learner
- ``config``: the resolved training config as a plain dict (``config["env"]`` is the env's
  ``_target_`` node, which ``rlgrasp.config.env_factory`` builds)
- ``spec``: ``obs_key``, ``obs_dim``, ``action_dim``, ``action_low``, ``action_high``
- ``versions``: python, torch, torchrl, tensordict, gymnasium, pybullet, rlgrasp
- ``run_dir``: the run directory it was written in
"""

from __future__ import annotations

import os
import random
import re
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import OmegaConf
from tensordict.nn import TensorDictModuleBase

from rlgrasp.train.models import OBS_KEY, RunningNorm, build_actor

FORMAT = 1
_NUMBERED = re.compile(r"ckpt_(\d+)\.pt$")


def save_checkpoint(path: str | os.PathLike, state: dict[str, Any]) -> Path:
    """Write ``state`` to ``path`` atomically: a crash mid-write never leaves a broken file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    torch.save(state, tmp)
    os.replace(tmp, path)
    return path


def load_checkpoint(path: str | os.PathLike, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Load a checkpoint file, or ``<run dir>/checkpoints/last.pt`` when given a run directory."""
    path = Path(path)
    if path.is_dir():
        path = path / "checkpoints" / "last.pt"
    # weights_only=False: the dict holds numpy RNG state and plain Python config values.
    return torch.load(path, map_location=map_location, weights_only=False)


def rng_state() -> dict[str, Any]:
    return {
        "python": random.getstate(),
        "numpy": np.random.get_state(),
        "torch": torch.get_rng_state(),
    }


def set_rng_state(state: dict[str, Any]) -> None:
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"])


def package_versions() -> dict[str, str]:
    out = {"python": sys.version.split()[0]}
    for name in ("torch", "torchrl", "tensordict", "gymnasium", "pybullet", "hydra-core", "rlgrasp"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "unknown"
    return out


def write_checkpoints(
    ckpt_dir: str | os.PathLike, state: dict[str, Any], keep_last: int, is_best: bool
) -> Path:
    """Write ``ckpt_<frames>.pt`` and ``last.pt`` (and ``best.pt``), keep the last K numbered ones."""
    ckpt_dir = Path(ckpt_dir)
    numbered = save_checkpoint(ckpt_dir / f"ckpt_{state['frames']:010d}.pt", state)
    save_checkpoint(ckpt_dir / "last.pt", state)
    if is_best:
        save_checkpoint(ckpt_dir / "best.pt", state)
    olds = sorted(p for p in ckpt_dir.glob("ckpt_*.pt") if _NUMBERED.search(p.name))
    for old in olds[: max(len(olds) - max(keep_last, 1), 0)]:
        old.unlink(missing_ok=True)
    return numbered


def policy_from_checkpoint(
    ckpt: dict[str, Any] | str | os.PathLike, device: str | torch.device = "cpu"
) -> TensorDictModuleBase:
    """The deterministic policy (normalizer included) from a checkpoint alone.

    Reads ``ckpt["observation"]`` from a tensordict and writes ``"action"`` (the distribution's mode).
    Accepts a loaded dict, a checkpoint path or a run directory.
    """
    if not isinstance(ckpt, dict):
        ckpt = load_checkpoint(ckpt, map_location=device)
    spec = ckpt["spec"]
    model_cfg = OmegaConf.create(ckpt["config"]["model"])
    norm = RunningNorm(spec["obs_dim"], clip=model_cfg.obs_clip, enabled=model_cfg.obs_norm)
    actor = build_actor(
        norm,
        spec["obs_dim"],
        torch.as_tensor(spec["action_low"]),
        torch.as_tensor(spec["action_high"]),
        model_cfg,
        deterministic=True,
    )
    actor.load_state_dict(ckpt["actor"])
    assert spec.get("obs_key", OBS_KEY) == OBS_KEY
    return actor.to(device).eval()
