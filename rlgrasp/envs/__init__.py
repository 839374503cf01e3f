"""The grasp-and-lift environment, split the panda-gym way: each part owns its bodies and state.

``scene`` (physics client, ground, the object body), ``robot`` (the arm interface and the Panda),
``control`` (how actions drive the arm), ``task`` (the object, success, reward), ``objects`` (object
sets), ``randomization`` (per-episode physics and sensing), ``observation`` (named parts) and
``grasp_env`` (the gymnasium env that sequences them).
"""

import os
import sys


def _import_pybullet_quietly() -> None:
    """PyBullet prints its build time on stderr, from C, when first imported: every entry point's
    one-line error would be two lines. Imported here first with stderr muted, it never prints."""
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()

from rlgrasp.envs.control import CONTROL_MODES  # noqa: E402
from rlgrasp.envs.experts import ScriptedExpert, expert_for  # noqa: E402
from rlgrasp.envs.grasp_env import GraspEnv  # noqa: E402
from rlgrasp.envs.randomization import PARAMS, PRESETS, Randomizer, Range  # noqa: E402

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
    "expert_for",
]
