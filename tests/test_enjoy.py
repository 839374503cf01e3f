"""rlgrasp-enjoy without a GUI: the no-display line, real-time pacing, the per-episode outcome lines,
and the same episodes as rlgrasp-eval (same seeds, same outcomes); with Xvfb, the GUI itself."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rlgrasp.compose import compose_config
from rlgrasp.evaluation.enjoy import PacedActor, no_display_reason, play, register_enjoy_config
from rlgrasp.evaluation.episodes import run_episode
from rlgrasp.evaluation.policies import build_policy
from rlgrasp.evaluation.source import EvaluationError, prepare
from tests.helpers import make_run, our_lines

ROOT = Path(__file__).resolve().parents[1]


def _cfg(*overrides: str):
    register_enjoy_config()
    return compose_config("enjoy", list(overrides))


def test_no_display_is_one_line_not_a_crash(tmp_path: Path) -> None:
    assert no_display_reason({}, "linux").startswith("no display")
    assert no_display_reason({"DISPLAY": ":0"}, "linux") is None
    assert no_display_reason({"WAYLAND_DISPLAY": "wayland-0"}, "linux") is None
    assert no_display_reason({}, "darwin") is None
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "enjoy.py"), "policy=scripted"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )
    if sys.platform.startswith("linux"):
        assert done.returncode == 1 and "Traceback" not in done.stderr
        assert our_lines(done.stderr) == [no_display_reason({}, "linux")]


def test_pacing_holds_each_step_to_its_slot() -> None:
    now, sleeps = [0.0], []

    class Fixed:
        def reset(self, seed: int) -> None:
            pass

        def __call__(self, obs):
            now[0] += 0.01  # the policy and the physics take 10 ms of the 50 ms slot
            return obs

    def sleep(s: float) -> None:
        sleeps.append(s)
        now[0] += s

    paced = PacedActor(Fixed(), 0.05, clock=lambda: now[0], sleep=sleep)
    paced.reset(0)
    for _ in range(5):
        paced(0)
    assert len(sleeps) == 4 and all(abs(s - 0.04) < 1e-9 for s in sleeps)
    assert abs(now[0] - 0.21) < 1e-9  # 4 full slots + the last call's 10 ms


def test_play_prints_each_outcome_like_evaluation(tmp_path: Path) -> None:
    run = make_run(tmp_path)
    lines: list[str] = []
    slept: list[float] = []
    results = play(
        _cfg(f"ckpt={run}", "episodes=2", "seed=5", "render=none"), out=lines.append, sleep=slept.append
    )
    assert lines[0].startswith("playing 2 episodes of ") and lines[0].endswith("at 20 Hz")
    assert [ln.split(":")[0] for ln in lines[1:3]] == [
        "episode 1/2 (seed 5, " + results[0].object + ")",
        "episode 2/2 (seed 6, " + results[1].object + ")",
    ]
    assert all(("success at step" in ln) or ("failed: " in ln) for ln in lines[1:3])
    assert lines[-1] == f"success {sum(r.success_at_end for r in results)}/2"
    assert slept  # paced to 20 Hz (the sleep was handed the waits)
    # The very episodes rlgrasp-eval runs for these seeds.
    source = prepare("checkpoint", str(run))
    env = source.make_env()
    try:
        actor = build_policy(source, env, deterministic=True)
        again = [run_episode(env, actor, i, 5 + i, render=False) for i in range(2)]
    finally:
        env.close()
    assert [(r.outcome, r.episode_return) for r in again] == [(r.outcome, r.episode_return) for r in results]


def test_bad_input_says_what(tmp_path: Path) -> None:
    with pytest.raises(EvaluationError, match="ckpt=.*required"):
        play(_cfg("render=none"), out=lambda s: None)
    with pytest.raises(EvaluationError, match="render=rgb: must be human or none"):
        play(_cfg("policy=scripted", "render=rgb"), out=lambda s: None)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb for a display")
@pytest.mark.parametrize("camera", [False, True])
def test_the_gui_opens_on_a_virtual_display(tmp_path: Path, camera: bool) -> None:
    """The GUI path itself (its visualizer settings, the camera preview panes), on Xvfb's display."""
    from tests.helpers import make_student

    ckpt = make_student(tmp_path) if camera else ROOT / "policies" / "grasp_ppo.pt"
    display = f":{90 + camera + os.getpid() % 50 * 2}"
    xvfb = subprocess.Popen(
        ["Xvfb", display, "-screen", "0", "1024x768x24"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        time.sleep(1.0)
        done = subprocess.run(
            [sys.executable, str(ROOT / "scripts" / "enjoy.py"), f"ckpt={ckpt}", "episodes=1", "speed=0"],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            timeout=300,
            env={**os.environ, "DISPLAY": display},
        )
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert "episode 1/1 (seed 0" in done.stdout
    assert ("camera: wrist depth 64x64" in done.stdout) == camera
