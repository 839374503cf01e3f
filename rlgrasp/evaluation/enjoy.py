"""Watch a policy live (``rlgrasp-enjoy``, like RL Zoo's ``enjoy``): the PyBullet GUI, real time.

The policy and the env are rebuilt from the checkpoint exactly as ``rlgrasp-eval`` does (same
checks, same seeds, same episode loop and outcome rules); only the env opens the GUI and each step
waits for its 1/20 s slot. For a camera policy the GUI's preview panes show what the camera
renders. Bad input is refused first, display or not (one line, exit code 2); then, without a
display, it says so in one line and exits with code 1.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import hydra
import numpy as np
import pybullet
from hydra.core.config_store import ConfigStore

from rlgrasp.config import CONFIG_DIR, register_configs
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.scene import VIEWER_TARGET
from rlgrasp.evaluation.episodes import run_episode
from rlgrasp.evaluation.policies import Actor, PolicySource, build_policy
from rlgrasp.evaluation.source import EvaluationError, prepare
from rlgrasp.overrides import entry_point
from rlgrasp.utils import plain


@dataclass
class EnjoyConfig:
    """``rlgrasp-enjoy``'s config (``configs/enjoy.yaml``)."""

    policy: str = "checkpoint"  # checkpoint | scripted | random
    ckpt: str | None = None  # a run directory (-> checkpoints/<ckpt_kind>.pt) or a checkpoint file
    ckpt_kind: str = "best"  # best | last
    episodes: int = 5
    seed: int = 0  # episode i is reset with seed + i (the same episodes as rlgrasp-eval's)
    randomization: Any = None  # null: the policy's training randomization (as rlgrasp-eval)
    env: dict[str, Any] = field(default_factory=dict)  # env keywords over the checkpoint's
    deterministic: bool = True
    speed: float = 1.0  # x real time (20 Hz control); 0: as fast as possible
    render: str = "human"  # human: the PyBullet GUI; none: no window (the same loop, for checks)


def register_enjoy_config() -> None:
    """Register ``EnjoyConfig`` as ``enjoy_schema`` (idempotent; called by the entry point)."""
    ConfigStore.instance().store(name="enjoy_schema", node=EnjoyConfig)


def no_display_reason(environ: dict[str, str] | None = None, platform: str | None = None) -> str | None:
    """Why the GUI cannot open here, in one line, or ``None`` when it can."""
    environ = os.environ if environ is None else environ
    platform = platform or sys.platform
    if platform.startswith("linux") and not (environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY")):
        return (
            "no display: the PyBullet GUI needs one (DISPLAY is unset). Use a desktop session, ssh -X, "
            "or xvfb-run; without a screen, scripts/evaluate.py writes videos instead."
        )
    return None


class PacedActor(Actor):
    """Holds each action back until its slot: one env step per ``period`` seconds of wall time."""

    def __init__(
        self,
        actor: Actor,
        period: float,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.actor, self.period, self.clock, self.sleep = actor, period, clock, sleep
        self.next_tick: float | None = None

    def reset(self, seed: int) -> None:
        self.actor.reset(seed)
        self.next_tick = None

    def __call__(self, obs: Any) -> np.ndarray:
        action = self.actor(obs)
        now = self.clock()
        if self.next_tick is None:
            self.next_tick = now
        if self.next_tick > now:
            self.sleep(self.next_tick - now)
        self.next_tick += self.period
        return action


def episode_line(i: int, n: int, r: Any) -> str:
    """``episode 2/5 (seed 1, cube/1.0): success at step 31 | return 23.10 | lift 6.1 cm``."""
    what = f"success at step {r.first_success_step}" if r.success_at_end else f"failed: {r.outcome}"
    name = f", {r.object}" if r.object else ""
    return (
        f"episode {i + 1}/{n} (seed {r.seed}{name}): {what} | return {r.episode_return:.2f} "
        f"| lift {100 * r.max_lift_height:.1f} cm | {r.length} steps"
    )


def gui_settings(env: Any) -> list[tuple[int, int]]:
    """``configureDebugVisualizer`` flags for watching ``env``: the side panels off for a state env;
    for a camera env on, with the synthetic camera's preview panes of what the policy reads (the
    env's ``getCameraImage`` calls appear there, before the sensor noise is added)."""
    camera = getattr(env.unwrapped, "camera", None)
    if camera is None:
        return [(pybullet.COV_ENABLE_GUI, 0)]
    keys = camera.spec.keys
    return [
        (pybullet.COV_ENABLE_GUI, 1),
        (pybullet.COV_ENABLE_RGB_BUFFER_PREVIEW, int("rgb" in keys)),
        (pybullet.COV_ENABLE_DEPTH_BUFFER_PREVIEW, int("depth" in keys)),
        (pybullet.COV_ENABLE_SEGMENTATION_MARK_PREVIEW, 0),
    ]


def set_up_gui(env: Any, client: Any = None) -> None:
    """The GUI's panels (``gui_settings``) and its camera where the videos look from."""
    client = client or env.unwrapped.client
    for flag, value in gui_settings(env):
        client.configureDebugVisualizer(flag, value)
    viewer = env.unwrapped.viewer
    client.resetDebugVisualizerCamera(viewer["distance"], viewer["yaw"], viewer["pitch"], list(VIEWER_TARGET))


def camera_line(env: Any) -> str | None:
    """What a camera env's policy sees, and where to watch it; ``None`` without a camera."""
    camera = getattr(env.unwrapped, "camera", None)
    if camera is None:
        return None
    s = camera.spec
    return (
        f"camera: {s.mount} {s.modality} {s.width}x{s.height}; the GUI's preview panes show what it "
        "renders (before the sensor noise the policy also gets)"
    )


def _print(line: str) -> None:
    print(line, flush=True)


def check(cfg: Any) -> PolicySource:
    """Every value, the checkpoint, the env and one policy step (``prepare``'s dry run), without a
    window: ``EvaluationError`` naming the first problem."""
    if cfg.render not in ("human", "none"):
        raise EvaluationError(f"render={cfg.render}: must be human or none")
    for key, minimum in (("episodes", 1), ("seed", 0), ("speed", 0)):
        if not cfg[key] >= minimum:
            raise EvaluationError(f"{key}={cfg[key]}: must be at least {minimum}")
    return prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, plain(cfg.randomization), plain(cfg.env))


def play(
    cfg: Any,
    out: Callable[[str], None] = _print,
    sleep: Callable[[float], None] = time.sleep,
    source: PolicySource | None = None,
) -> list:
    """Play ``cfg.episodes`` episodes (of ``source``, else ``check(cfg)``'s), one line per episode;
    the results."""
    source = source or check(cfg)
    env = env_factory({**source.env_cfg, "render_mode": "human" if cfg.render == "human" else None})()
    try:
        if cfg.render == "human":
            set_up_gui(env)
        fps = env.metadata.get("render_fps", 20)
        actor = build_policy(source, env, cfg.deterministic)
        if cfg.speed > 0:
            actor = PacedActor(actor, 1.0 / (fps * cfg.speed), sleep=sleep)
        out(f"playing {cfg.episodes} episodes of {source.ckpt_path or cfg.policy} at {fps * cfg.speed:g} Hz")
        if camera_line(env):
            out(camera_line(env))
        results = []
        for i in range(cfg.episodes):
            start = time.perf_counter()
            results.append(run_episode(env, actor, i, cfg.seed + i, render=False))
            hz = results[-1].length / (time.perf_counter() - start)
            line = episode_line(i, cfg.episodes, results[-1])
            if cfg.speed > 0 and hz < 0.9 * fps * cfg.speed:  # e.g. software OpenGL on a busy machine
                line += f" | ran at {hz:.1f} Hz, slower than real time"
            out(line)
    finally:
        env.close()
    wins = sum(r.success_at_end for r in results)
    out(f"success {wins}/{len(results)}")
    return results


def run(cfg: Any) -> None:
    """``play``; bad input (checked first, with or without a display) one line and exit code 2,
    no display one line and exit code 1."""
    try:
        source = check(cfg)
    except EvaluationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    reason = no_display_reason() if cfg.render == "human" else None
    if reason:
        print(reason, file=sys.stderr)
        sys.exit(1)
    try:
        play(cfg, source=source)
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)


def main() -> None:
    """Console entry point ``rlgrasp-enjoy`` (same as ``python scripts/enjoy.py``)."""
    register_configs()
    register_enjoy_config()
    hydra_main = hydra.main(config_path=CONFIG_DIR, config_name="enjoy", version_base="1.3")(run)
    entry_point("enjoy", open_env=True)(hydra_main)()
