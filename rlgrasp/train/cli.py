"""Console entry point ``rlgrasp-train`` (same as ``python scripts/train.py``).

The Hydra configs live at the repository root (``configs/``), next to the ``rlgrasp`` package, so
the console script needs a source checkout (``pip install -e .``); ``RLGRASP_CONFIG_DIR`` points it
at another config tree.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from rlgrasp.config import CONFIG_DIR, ConfigError, register_configs
from rlgrasp.overrides import entry_point
from rlgrasp.policy_file import CheckpointError
from rlgrasp.received import ReceivedError
from rlgrasp.rundir import remove_refused_start
from rlgrasp.train.loop import TrainingError, train
from rlgrasp.train.resume import command_line_keys

register_configs()
log = logging.getLogger("rlgrasp.train")


def run(cfg: DictConfig) -> float:
    """Train with the configured algorithm (``algo=ppo``, ``sac``, or ``distill``: a camera student from
    a state teacher) and return the final evaluation success rate (what a Hydra sweeper optimizes).

    Bad input (a bad value, a resume that cannot be done) ends the process with exit code 2 and one
    line, and removes the run directory this command created; a fault (env crash, NaN) with exit
    code 1 and its message. Neither prints a traceback.
    """
    try:
        return train(cfg, changed=_command_line_keys(cfg))
    except (ConfigError, CheckpointError, ReceivedError) as exc:
        # As every entry point refuses bad input: one line on stderr (the run's log goes with its dir)
        print(f"error: {exc}", file=sys.stderr)
        remove_refused_start(Path(cfg.paths.output_dir))
        sys.exit(2)
    except TrainingError as exc:
        log.error("training stopped: %s", exc)
        sys.exit(1)


def _command_line_keys(cfg: DictConfig) -> set[str] | None:
    """The keys this command line sets (what a resume applies over the checkpoint's config)."""
    if not cfg.resume or not HydraConfig.initialized():
        return None
    return command_line_keys(list(HydraConfig.get().overrides.task), cfg)


@entry_point("train")  # objects={paths:[...]} as in evaluation; a refused command line in one line
@hydra.main(config_path=CONFIG_DIR, config_name="train", version_base="1.3")
def main(cfg: DictConfig) -> float:
    return run(cfg)


if __name__ == "__main__":
    main()
