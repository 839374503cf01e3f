"""Hyperparameter sweep: python scripts/sweep.py experiment=grasp_ppo sweep=grasp_ppo [overrides ...]."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.sweep.cli import main

if __name__ == "__main__":
    sys.exit(main())
