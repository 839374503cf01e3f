"""benchmarks/bench_expert.py's off-centre expert: it aims its grasp point ``offset`` metres along the
pads from where the plain expert aims."""

import runpy
from pathlib import Path

import numpy as np
import pytest

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def env():
    env = PandaGraspEnv(randomization="none", objects="cube", control={"ee_yaw": False})
    yield env
    env.close()


def test_the_off_centre_expert_aims_along_the_pads(env) -> None:
    off_centre = runpy.run_path(str(ROOT / "benchmarks" / "bench_expert.py"))["OffCentreExpert"]
    obs, _ = env.reset(seed=0)
    obs = obs.copy()
    part = env.obs_slices["object_minus_grasp"]
    obs[part] = [0.0, 0.0, -0.02]  # the hand right above the cube: its moves are not clipped
    plain, shifted = ScriptedExpert.for_env(env), off_centre.for_env(env, offset=0.01)
    # At yaw 0 the fingers close along y, so the pads run along x: 1 cm more of x to go, at the
    # expert's gain of 0.8 per 4 cm step.
    difference = shifted(obs) - plain(obs)
    np.testing.assert_allclose(difference, [0.2, 0.0, 0.0, 0.0], atol=1e-5)
