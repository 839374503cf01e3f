"""Record demonstrations: python scripts/demos.py episodes=200 out=demos/cube [objects=... policy=<ckpt>]."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.demos.cli import main  # noqa: E402

if __name__ == "__main__":
    main()
