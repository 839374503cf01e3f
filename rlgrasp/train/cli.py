"""Console entry point ``rlgrasp-train`` (same as ``python scripts/train.py``).

The Hydra configs live at the repository root (``configs/``), next to the ``rlgrasp`` package, so
the console script needs a source checkout (``pip install -e .``); ``RLGRASP_CONFIG_DIR`` points it
at another config tree.
"""

from __future__ import annotations

import logging
import sys

import hydra
from omegaconf import DictConfig

from rlgrasp.config import CONFIG_DIR, register_configs

register_configs()


def run(cfg: DictConfig) -> float:
    """Train and return the final evaluation success rate (what a Hydra sweeper optimizes).

    A fault (env crash, NaN) ends the process with exit code 1 and its message, without a
    traceback through Hydra's machinery.
    """
    from rlgrasp.train.loop import TrainingError, train

    try:
        return train(cfg)
    except TrainingError as exc:
        logging.getLogger("rlgrasp.train").error("training stopped: %s", exc)
        sys.exit(1)


@hydra.main(config_path=CONFIG_DIR, config_name="train", version_base="1.3")
def main(cfg: DictConfig) -> float:
    return run(cfg)


if __name__ == "__main__":
    main()
