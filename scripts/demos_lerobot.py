"""Demonstrations to and from LeRobot datasets (v3.0, images as PNG; needs the ``lerobot`` extra).

    python scripts/demos_lerobot.py export demos/cube/demos datasets/cube            # a new dataset folder
    python scripts/demos_lerobot.py import datasets/cube demos/cube_lerobot          # -> <out>/demos
    python scripts/demos_lerobot.py import <a dataset recorded elsewhere> demos/theirs robot=xarm6 task=push

The same as ``rlgrasp-demos-lerobot``; docs/sparse.md#lerobot-datasets says what maps to what.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.demos.lerobot import main  # noqa: E402

if __name__ == "__main__":
    main()
