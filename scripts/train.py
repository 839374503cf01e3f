"""Train a grasping policy: python scripts/train.py experiment=grasp_ppo [key=value ...]."""

import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
from rlgrasp.config import register_configs
from rlgrasp.overrides import entry_point
from rlgrasp.train.cli import run

register_configs()


@entry_point("train")  # objects={paths:[...]} as in evaluation; a refused command line in one line
@hydra.main(config_path="../configs", config_name="train", version_base="1.3")
def main(cfg: DictConfig) -> float:
    return run(cfg)


if __name__ == "__main__":
    main()
