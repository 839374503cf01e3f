"""docs/tutorial.md runs as written: its blocks are the sections of examples/tutorial.py, which these
tests run (the quick steps in the quick set, every step in the complete suite)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "examples" / "tutorial.py"


def run_steps(tmp_path: Path, *steps: str) -> str:
    env = {**os.environ, "RLGRASP_TUTORIAL_OUT": str(tmp_path / "tutorial")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    done = subprocess.run(
        [sys.executable, str(SCRIPT), *steps], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done.stdout


def test_every_block_of_the_page_is_a_section_of_the_script():
    page = (ROOT / "docs" / "tutorial.md").read_text()
    script = SCRIPT.read_text()
    names = re.findall(r'--8<-- "examples/tutorial\.py:(\w+)"', page)
    assert len(names) == 7
    for name in names:
        assert f"# --8<-- [start:{name}]" in script and f"# --8<-- [end:{name}]" in script, name


def test_scene_control_and_env_steps(tmp_path):
    out = run_steps(tmp_path, "scene", "control", "env")
    assert "panda_finger_joint1 prismatic" in out
    joint_error = float(re.search(r"largest error \(rad\) ([\d.e-]+)", out)[1])
    ik_error = float(re.search(r"IK: .* error \(m\) ([\d.e-]+)", out)[1])
    assert joint_error < 0.01 and ik_error < 0.03
    assert "the scripted expert: " in out and "success True" in out


@pytest.mark.full
def test_every_step(tmp_path):
    out = run_steps(tmp_path)
    for step in ("scene", "control", "env", "train", "sparse", "randomization", "workers"):
        assert f"--- {step}" in out
    assert "with demonstrations, final evaluation success" in out
    assert "held-out meshes: success" in out
    assert (tmp_path / "tutorial" / "smoke" / "eval" / "metrics.json").is_file()
