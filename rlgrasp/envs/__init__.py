"""The Panda grasp-and-lift environment, split the panda-gym way: scene, robot, task, randomizer."""

from rlgrasp.envs.expert import ScriptedExpert
from rlgrasp.envs.panda_grasp import CONTROL_MODES, PandaGraspEnv
from rlgrasp.envs.randomization import PARAMS, PRESETS, Randomizer, Range

__all__ = [
    "CONTROL_MODES",
    "PARAMS",
    "PRESETS",
    "PandaGraspEnv",
    "Randomizer",
    "Range",
    "ScriptedExpert",
]
