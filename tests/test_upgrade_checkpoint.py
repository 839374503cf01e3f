"""scripts/upgrade_checkpoint.py: format-1 checkpoints become loadable with weights_only=True, only
when trusted; --policy-only files evaluate but hold no optimizer or RNG state."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from rlgrasp.policy_file import read_checkpoint
from tests.helpers import make_run

ROOT = Path(__file__).resolve().parents[1]


def _format_one(tmp_path: Path) -> Path:
    """A checkpoint as format 1 wrote it: RNG states as Python and numpy objects."""
    state = read_checkpoint(make_run(tmp_path) / "checkpoints" / "last.pt")
    state["format"] = 1
    state["rng"] = {
        "python": random.getstate(),
        "numpy": np.random.get_state(),
        "torch": torch.get_rng_state(),
    }
    path = tmp_path / "v1.pt"
    torch.save(state, path)
    return path


def _upgrade(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, str(ROOT / "scripts" / "upgrade_checkpoint.py"), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_upgrade_needs_trust_then_loads_weights_only(tmp_path: Path) -> None:
    old = _format_one(tmp_path)
    refused = _upgrade(str(old), str(tmp_path / "no.pt"))
    assert refused.returncode != 0 and "--trust" in refused.stderr and "Traceback" not in refused.stderr
    assert not (tmp_path / "no.pt").exists()

    assert _upgrade(str(old), str(tmp_path / "v2.pt"), "--trust").returncode == 0
    state = read_checkpoint(tmp_path / "v2.pt")  # weights_only=True
    assert state["format"] == 2 and isinstance(state["rng"]["numpy"]["keys"], torch.Tensor)
    original = torch.load(old, weights_only=False)
    assert torch.equal(state["rng"]["torch"], original["rng"]["torch"])
    assert state["rng"]["python"]["state"].tolist() == list(original["rng"]["python"][1])

    assert _upgrade(str(tmp_path / "v2.pt"), str(tmp_path / "policy.pt"), "--policy-only").returncode == 0
    policy = read_checkpoint(tmp_path / "policy.pt")
    assert "optimizer" not in policy and "rng" not in policy
    assert all(torch.equal(policy["actor"][k], v) for k, v in state["actor"].items())
