"""Rewrite a checkpoint so that ``weights_only=True`` loads it, optionally as a policy-only file.

Format-1 checkpoints (written before checkpoints held only tensors and plain containers) store
the RNG states as numpy and Python objects, so resume and evaluation refuse them. Loading one
means unpickling arbitrary objects, which can run code: do it only for files you made yourself,
hence ``--trust``. ``--policy-only`` keeps what evaluation and export read (actor with its
normalizer, config, spec, counters, versions) and drops the optimizer, critic and RNG states: a
small file to share or ship, which cannot be resumed. The config comes out in today's shape, read as
data (``rlgrasp.received``: each part by rlgrasp's own class for its short name, ``algo``'s keys by
role, the logger only named).

    python scripts/upgrade_checkpoint.py outputs/train/x/run/checkpoints/last.pt upgraded.pt --trust
    python scripts/upgrade_checkpoint.py <run>/checkpoints/best.pt policies/grasp_ppo.pt --policy-only
"""

from __future__ import annotations

import argparse
import random
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout, uninstalled

from rlgrasp import policy_file  # noqa: E402
from rlgrasp.received import ReceivedError, read_config  # noqa: E402
from rlgrasp.train import checkpoint as ckpt_lib  # noqa: E402

POLICY_KEYS = (
    "kind",
    "actor",
    "config",
    "spec",
    "frames",
    "updates",
    "best_eval_success",
    "last_eval",
    "versions",
)


def load(path: Path, trust: bool) -> dict:
    try:
        return policy_file.read_checkpoint(path)
    except policy_file.CheckpointError as exc:
        if not trust or not str(exc).startswith("refused checkpoint"):
            hint = "" if trust else " (a file you made: --trust)"
            raise SystemExit(f"upgrade_checkpoint: {exc}{hint}") from None
    state = torch.load(path, map_location="cpu", weights_only=False)
    if state.get("format", 1) == 1 and "rng" in state:
        # Through the RNGs themselves, so the format-2 encoding is the one the Trainer writes.
        random.setstate(state["rng"]["python"])
        np.random.set_state(state["rng"]["numpy"])
        torch.set_rng_state(state["rng"]["torch"])
        state["rng"] = ckpt_lib.rng_state()
    state.pop("obs_norm", None)  # format 1 kept a copy of the normalizer the actor already holds
    try:  # unpickled because you trust the file; its config is still read as data (rlgrasp.received)
        state["config"] = read_config(state["config"], str(path))
    except ReceivedError as exc:
        raise SystemExit(f"upgrade_checkpoint: {exc}") from None
    state["format"] = policy_file.CHECKPOINT_FORMAT
    return state


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("src", type=Path)
    parser.add_argument("dst", type=Path)
    parser.add_argument("--trust", action="store_true", help="unpickle a format-1 file (one you made)")
    parser.add_argument("--policy-only", action="store_true", help="keep what evaluation and export need")
    args = parser.parse_args()
    state = load(args.src, args.trust)
    if args.policy_only:
        state = {"format": policy_file.CHECKPOINT_FORMAT, **{k: state[k] for k in POLICY_KEYS if k in state}}
    ckpt_lib.save_checkpoint(args.dst, state)
    policy_file.read_checkpoint(args.dst)  # proves the result loads with weights_only=True
    size_kb = args.dst.stat().st_size / 1024
    print(f"wrote {args.dst} ({size_kb:.0f} kB, format {policy_file.CHECKPOINT_FORMAT})")


if __name__ == "__main__":
    main()
