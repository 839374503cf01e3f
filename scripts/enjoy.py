"""Watch a policy live in the PyBullet GUI: python scripts/enjoy.py ckpt=<run dir or .pt> [episodes=5]."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.evaluation.enjoy import main  # noqa: E402

if __name__ == "__main__":
    main()
