"""Learning quality: the default experiment lifts the cube. Slow (~3 min on 2 cores): run with
``python -m pytest -m slow tests/test_learning.py``."""

from __future__ import annotations

import pytest

from rlgrasp.train.loop import train


@pytest.mark.slow
def test_grasp_ppo_learns_to_lift(train_cfg) -> None:
    cfg = train_cfg("experiment=grasp_ppo", "seed=0", "total_frames=150000", "logger=none")
    # A random or reach-only policy scores 0 here; the scripted expert 0.98.
    assert train(cfg) >= 0.75
