"""Export a trained policy: python scripts/export.py ckpt=<run dir or .pt> format=torchscript|onnx|pt2|all."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.export import main  # noqa: E402

if __name__ == "__main__":
    main()
