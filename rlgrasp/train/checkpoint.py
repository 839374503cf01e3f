"""Checkpoints as training writes them: atomic saves, retention, the RNG states.

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
  written before kept PPO's and DAgger's at the top level (``rlgrasp.legacy.algorithm_state``)
- ``frames``, ``updates``: counters; ``generation``: how many times the run was resumed
- ``best_eval_success``, ``last_eval``: evaluation bookkeeping (``last_eval`` may be None)
- ``rng``: python / numpy / torch RNG states of the learner, as tensors and plain values
- ``config``: the resolved training config as a plain dict (``config["env"]`` is the env's
  ``_target_`` node, which ``rlgrasp.envs.factory.env_factory`` builds); an older checkpoint's is
  read in today's shape (``rlgrasp.legacy``)
- ``spec``: ``obs_key``, ``obs_dim``, ``action_dim``, ``action_low``, ``action_high``
- ``versions``: python, torch, torchrl, tensordict, gymnasium, pybullet, rlgrasp
- ``run_dir``: the run directory it was written in
- a demonstration file is referenced by ``config["algo"]["demos"]``, not stored

Only tensors and plain containers are stored, and every reader loads with ``weights_only=True``: a
checkpoint someone sends cannot run code when it is loaded, and one that would need to unpickle any
other object is refused (``CheckpointError``).

The readers (a file, a policy folder or a run directory, checked as received data) are in
``rlgrasp.policy_file``, below the training core, so that evaluation, export and deploy do not import it.
"""

from __future__ import annotations

import os
import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rlgrasp.errors import ConfigError
from rlgrasp.policy_file import NUMBERED


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


def numbered_path(ckpt_dir: str | os.PathLike, frames: int) -> Path:
    """``ckpt_<frames>.pt``: written after ``last.pt``, so its presence says ``last.pt`` holds these
    frames (frames only grow, and the newest numbered file is never pruned)."""
    return Path(ckpt_dir) / f"ckpt_{frames:010d}.pt"


def check_algorithm(state: dict[str, Any], name: str) -> None:
    """``ConfigError`` unless the checkpoint was trained by algorithm ``name`` (or does not say)."""
    saved = (state.get("config") or {}).get("algo", {}).get("name")
    if saved is not None and saved != name:
        raise ConfigError(
            f"algo: the checkpoint was trained with algo={saved}, not algo={name}; "
            f"resume it with algo={saved}, or start a new run (algo.init_from=<checkpoint> to warm start)"
        )


def restore_rng(state: dict[str, Any]) -> None:
    """The RNG state a checkpoint saved (``set_rng_state``); ``ConfigError`` when it is unreadable."""
    try:
        set_rng_state(state["rng"])
    except (KeyError, TypeError, ValueError, AttributeError, RuntimeError) as exc:
        raise ConfigError(f"checkpoint's rng state is unreadable ({type(exc).__name__}: {exc})") from None


def write_checkpoints(
    ckpt_dir: str | os.PathLike, state: dict[str, Any], keep_last: int, is_best: bool
) -> Path:
    """Write ``last.pt`` first, then ``ckpt_<frames>.pt`` (and ``best.pt``), and keep the last K
    numbered ones: an interruption between the writes leaves ``last.pt`` the newest, which is what a
    resume reads first. Separate files, not links: a ``last.pt`` damaged in place leaves the
    numbered ones to resume from."""
    ckpt_dir = Path(ckpt_dir)
    save_checkpoint(ckpt_dir / "last.pt", state)
    numbered = save_checkpoint(numbered_path(ckpt_dir, state["frames"]), state)
    if is_best:
        save_checkpoint(ckpt_dir / "best.pt", state)
    olds = sorted(p for p in ckpt_dir.glob("ckpt_*.pt") if NUMBERED.search(p.name))
    for old in olds[: max(len(olds) - max(keep_last, 1), 0)]:
        old.unlink(missing_ok=True)
    return numbered
