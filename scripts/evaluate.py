"""Evaluate a policy: python scripts/evaluate.py ckpt=<run dir or checkpoint> [key=value ...].

Baselines: python scripts/evaluate.py policy=scripted (or policy=random). See docs/evaluation.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.evaluation.cli import main  # noqa: E402

if __name__ == "__main__":
    main()
