"""The grasp-and-lift environment, split the panda-gym way: each part owns its bodies and state.

``scene`` (physics client, ground, the object body), ``robot`` (the arm interface and the Panda),
``control`` (how actions drive the arm), ``task`` (the object, success, reward), ``objects`` (object
sets), ``randomization`` (per-episode physics and sensing), ``observation`` (named parts) and
``grasp_env`` (the gymnasium env that sequences them).
"""

from rlgrasp.envs.control import CONTROL_MODES
from rlgrasp.envs.expert import ScriptedExpert
from rlgrasp.envs.grasp_env import GraspEnv
from rlgrasp.envs.randomization import PARAMS, PRESETS, Randomizer, Range

#: The name configs and checkpoints written before the robot seam use as ``env._target_``.
PandaGraspEnv = GraspEnv

__all__ = [
    "CONTROL_MODES",
    "PARAMS",
    "PRESETS",
    "GraspEnv",
    "PandaGraspEnv",
    "Randomizer",
    "Range",
    "ScriptedExpert",
]
