"""Compare runs: python scripts/report.py <run dirs or globs> [--out DIR] (same as rlgrasp-report)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.evaluation.report import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
