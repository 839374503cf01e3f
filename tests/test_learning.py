"""Learning quality: the default experiment lifts the cube. Slow (~3 min on 2 cores): run with
``python -m pytest -m slow tests/test_learning.py``."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from rlgrasp.train.config import register_configs
from rlgrasp.train.loop import train

CONFIG_DIR = str(Path(__file__).resolve().parents[1] / "configs")


@pytest.mark.slow
def test_grasp_ppo_learns_to_lift(tmp_path: Path) -> None:
    register_configs()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            config_name="train",
            overrides=[
                "experiment=grasp_ppo",
                "seed=0",
                "total_frames=150000",
                "logger=none",
                f"paths.output_dir={tmp_path}",
            ],
        )
    # A random or reach-only policy scores 0 here; the scripted expert 0.98.
    assert train(cfg) >= 0.75
