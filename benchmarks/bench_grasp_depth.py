"""Where a policy's hand closes on the object, by outcome: where a slipping grasp differs.

At the first step both fingers touch the object (``info["grasped"]``) it reads the observation's
``object_minus_grasp`` (the object's centre minus the grasp point): its height is the grasp's depth
(positive: the grasp point below the centre), its horizontal length the grasp's offset from the
centre (the lever gravity turns the object about the fingers with); then it counts the steps the
fingers hold it and, where they let go before the end, at which step, how high and how far the
object's tilt had changed since the first grasp. Episodes are the evaluation's seeded ones
(episode i reset with ``seed`` + i, 0-99 by default) and each gets the evaluation's outcome
(``success`` or a failure reason, ``rlgrasp.evaluation.outcomes``), so grasps that held and that
``slipped`` compare directly. docs/history/robots.md ("Where a learned grasp closes", "How a learned grasp
lets go") was measured with it. The arguments are ``rlgrasp-eval``'s keys:

    python benchmarks/bench_grasp_depth.py ckpt=policies/grasp_ppo_xarm6.pt episodes=100
    python benchmarks/bench_grasp_depth.py policy=scripted robot=xarm6 env.control.ee_yaw=true episodes=100

Why not ``rlgrasp-eval``: its episode runner keeps what every policy is judged by (success, lift,
outcome), not one observation part at one step; this reads that part with the same rules.
"""

from __future__ import annotations

import collections
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from rlgrasp.compose import compose_eval
from rlgrasp.evaluation.outcomes import SUCCESS, failure_reason
from rlgrasp.evaluation.policies import build_policy
from rlgrasp.evaluation.source import prepare
from rlgrasp.overrides import rewrite
from rlgrasp.utils import plain


@dataclass
class Grasp:
    """Where the hand first closed on the object, and for how many steps it held it."""

    depth: float  # m: the object's centre minus the grasp point, in height (> 0: below the centre)
    offset: float  # m: the same, horizontally (how far off the centre the fingers close)
    tilt: float  # rad: the object's tilt then
    steps_held: int = 0
    # Where the fingers last let go of it, when they did: the step, its height above its rest, and
    # how far it had turned in the grip since the first grasp (rad).
    let_go: tuple[int, float, float] | None = None


def first_grasp(env: Any, actor: Any, seed: int) -> tuple[str, Grasp | None]:
    """One seeded episode: its outcome, and its first grasp (None when the hand never closed on it)."""
    obs, info = env.reset(seed=seed)
    actor.reset(seed)
    part = getattr(env, "obs_slices", None) or env.unwrapped.obs_slices
    held, tilts, grasp = [bool(info.get("grasped", False))], [float(info.get("object_tilt", 0.0))], None
    while True:
        obs, _, terminated, truncated, info = env.step(actor(obs))
        grasped, tilt = bool(info.get("grasped", False)), float(info.get("object_tilt", 0.0))
        if grasped and grasp is None:
            state = obs["state"] if isinstance(obs, dict) else obs
            centre_minus_grasp = np.asarray(state)[part["object_minus_grasp"]]
            grasp = Grasp(float(centre_minus_grasp[2]), float(np.linalg.norm(centre_minus_grasp[:2])), tilt)
        if grasp is not None:
            grasp.steps_held += grasped
            if held[-1] and not grasped:
                grasp.let_go = (len(held), float(info.get("lift_height", 0.0)), tilt - grasp.tilt)
            elif grasped:
                grasp.let_go = None
        held.append(grasped)
        tilts.append(tilt)
        if terminated or truncated:
            break
    if info.get("is_success", False):
        return SUCCESS, grasp
    return failure_reason(held, tilts, info.get("object_extents", (0.0, 0.0, 0.0))), grasp


def main(overrides: list[str]) -> dict[str, list[Grasp | None]]:
    cfg = compose_eval(rewrite(overrides, open_env=True))  # env.<key>= as rlgrasp-eval takes it
    source = prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, plain(cfg.randomization), plain(cfg.env))
    env = source.make_env()
    actor = build_policy(source, env, deterministic=bool(cfg.deterministic))
    by_outcome: dict[str, list[Grasp | None]] = collections.defaultdict(list)
    for seed in range(int(cfg.seed), int(cfg.seed) + int(cfg.episodes)):
        outcome, grasp = first_grasp(env, actor, seed)
        by_outcome[outcome].append(grasp)
    env.close()
    print(
        "| outcome | episodes | grasped | depth, cm: mean (median) | offset, cm: mean (median) | held |"
        " let go: episodes, step, lift m, tilt change rad (medians) |"
    )
    print("|---|---|---|---|---|---|---|")
    for outcome, grasps in sorted(by_outcome.items(), key=lambda kv: -len(kv[1])):
        print(f"| {outcome} | {len(grasps)} | {_cells([g for g in grasps if g is not None])} |")
    return dict(by_outcome)


def _cells(found: list[Grasp]) -> str:
    if not found:
        return "0 | - | - | - | -"
    depth, offset = ([100 * getattr(g, key) for g in found] for key in ("depth", "offset"))
    lost = [g.let_go for g in found if g.let_go is not None]
    let_go = f"{len(lost)}: " + ", ".join(f"{np.median(x):.2f}" for x in zip(*lost)) if lost else "0"
    return (
        f"{len(found)} | {np.mean(depth):.2f} ({np.median(depth):.2f}) | "
        f"{np.mean(offset):.2f} ({np.median(offset):.2f}) | "
        f"{np.mean([g.steps_held for g in found]):.1f} | {let_go}"
    )


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):
        sys.exit(print(__doc__))
    main(sys.argv[1:])
