"""Convert a policy (a ``.pt`` checkpoint or a run directory) into a policy folder others read without
unpickling: ``model.safetensors`` + ``config.json`` + a model card (``README.md``).

The same as ``rlgrasp-export ckpt=<src> format=folder out=<dst>``: the checkpoint is checked as
evaluation checks it, the folder is written beside ``dst`` and read back, and its actions must equal
the checkpoint's on ``--verify-obs`` recorded observations before it replaces ``dst`` (a folder that
is not a policy folder is never replaced).

    python scripts/policy_folder.py policies/grasp_ppo.pt policies/grasp_ppo
    python scripts/policy_folder.py <run dir> exported/my_policy --ckpt-kind last
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled

from rlgrasp.export import FOLDER, ExportConfig, run  # noqa: E402
from rlgrasp.overrides import OneLineParser  # noqa: E402


def main(argv: list[str] | None = None) -> dict[str, dict]:
    """Parse the command line and export the folder; a bad input is one line and exit code 2."""
    parser = OneLineParser(prog="policy_folder.py", description=__doc__.splitlines()[0])
    parser.add_argument("src", help="a .pt checkpoint, a run directory or a policy folder")
    parser.add_argument("dst", help="the policy folder to write (new, empty, or a policy folder)")
    parser.add_argument("--ckpt-kind", default="best", choices=("best", "last"), help="of a run directory")
    parser.add_argument("--verify-obs", type=int, default=200, help="observations compared (0: none)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="[%(levelname)s] %(message)s")
    cfg = ExportConfig(
        ckpt=args.src,
        ckpt_kind=args.ckpt_kind,
        format=FOLDER,
        out=args.dst,
        verify=args.verify_obs > 0,
        verify_obs=max(args.verify_obs, 1),
    )
    return run(cfg)


if __name__ == "__main__":
    main()
