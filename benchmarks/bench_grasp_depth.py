"""How deep a policy's hand closes on the object, by outcome: where a slipping grasp differs.

At the first step both fingers touch the object (``info["grasped"]``) it reads the observation's
``object_minus_grasp`` height (the object's centre minus the grasp point): positive means the grasp
point is below the centre. Episodes are the evaluation's seeded ones (episode i reset with
``seed`` + i, 0-99 by default) and each gets the evaluation's outcome (``success`` or a failure reason,
``rlgrasp.evaluation.outcomes``), so the depths of grasps that held and that ``slipped`` compare
directly. docs/robots.md ("Where a learned grasp closes") was measured with it. The arguments are
``rlgrasp-eval``'s keys:

    python benchmarks/bench_grasp_depth.py ckpt=policies/grasp_ppo_xarm6.pt episodes=100
    python benchmarks/bench_grasp_depth.py policy=scripted robot=xarm6 episodes=100

Why not ``rlgrasp-eval``: its episode runner keeps what every policy is judged by (success, lift,
outcome), not one observation part at one step; this reads that part with the same rules.
"""

from __future__ import annotations

import collections
import sys
from typing import Any

import numpy as np

from rlgrasp.compose import compose_eval
from rlgrasp.evaluation.outcomes import SUCCESS, failure_reason
from rlgrasp.evaluation.policies import build_policy
from rlgrasp.evaluation.source import prepare
from rlgrasp.utils import plain


def grasp_depth(env: Any, actor: Any, seed: int) -> tuple[str, float | None]:
    """One seeded episode: its outcome and the grasp depth (m) at its first grasped step, or None."""
    obs, info = env.reset(seed=seed)
    actor.reset(seed)
    part = getattr(env, "obs_slices", None) or env.unwrapped.obs_slices
    held, tilts, depth = [bool(info.get("grasped", False))], [float(info.get("object_tilt", 0.0))], None
    while True:
        obs, _, terminated, truncated, info = env.step(actor(obs))
        grasped = bool(info.get("grasped", False))
        if grasped and depth is None:
            state = obs["state"] if isinstance(obs, dict) else obs
            depth = float(np.asarray(state)[part["object_minus_grasp"]][2])
        held.append(grasped)
        tilts.append(float(info.get("object_tilt", 0.0)))
        if terminated or truncated:
            break
    if info.get("is_success", False):
        return SUCCESS, depth
    return failure_reason(held, tilts, info.get("object_extents", (0.0, 0.0, 0.0))), depth


def main(overrides: list[str]) -> dict[str, list[float | None]]:
    cfg = compose_eval(overrides)
    source = prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, plain(cfg.randomization), plain(cfg.env))
    env = source.make_env()
    actor = build_policy(source, env, deterministic=bool(cfg.deterministic))
    by_outcome: dict[str, list[float | None]] = collections.defaultdict(list)
    for seed in range(int(cfg.seed), int(cfg.seed) + int(cfg.episodes)):
        outcome, depth = grasp_depth(env, actor, seed)
        by_outcome[outcome].append(depth)
    print(f"{'outcome':18s} {'episodes':>8s} {'grasped':>8s} {'mean depth':>11s} {'median':>8s}")
    for outcome, depths in sorted(by_outcome.items(), key=lambda kv: -len(kv[1])):
        cm = [100 * d for d in depths if d is not None]
        mean, median = (f"{np.mean(cm):.2f} cm", f"{np.median(cm):.2f}") if cm else ("-", "-")
        print(f"{outcome:18s} {len(depths):8d} {len(cm):8d} {mean:>11s} {median:>8s}")
    env.close()
    return dict(by_outcome)


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):
        sys.exit(print(__doc__))
    main(sys.argv[1:])
