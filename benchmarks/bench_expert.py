"""Success of the scripted expert over seeded episodes, per object set and randomization preset.

The expert is the proof that the task is solvable and the baseline a learned policy is compared
with. Seeds are first-seed..first-seed+N-1 (default 0..N-1), so the figures reproduce exactly.
Each failure gets one reason, read from the episode's info by the rules the evaluation uses
(``rlgrasp.evaluation.outcomes``): ``too wide``, ``tipped or rolled``, ``never grasped``,
``slipped`` or ``held, not lifted``.

    python benchmarks/bench_expert.py [--episodes 100] [--presets none default wide] [--objects cube]
        [--robot panda kuka_iiwa xarm6 configs/robot/my_arm.yaml] [--collision-model mesh|primitive]
        [--task lift|pick_place|push|stack]

``--task`` measures that task's expert (``rlgrasp.envs.experts``); a goal task's failures are
``goal not reached`` (the object's centre farther than the task's threshold at the end), ``held at
the end`` (stack: placed but not let go) or ``base moved``.

``--robot`` takes built-in arms by name and arm descriptions by file (a ``robot`` config group
file, e.g. a copy of ``rlgrasp/envs/robots/xarm6.yaml`` with one key changed: the guide "When your
arm slips" in docs/robots.md measures each change so).

``--offset M`` sends the expert's grasp point M metres off the object's centre along the pads
(across the fingers' closing axis), where learned policies close (0.7-1.2 cm off on the cube): how
far off the centre an arm's gripper still holds, the expert's grasp otherwise unchanged.

``--record PAGE/ID`` writes the successes per arm, object set and preset into that row of
docs/benchmarks/results.json and its page's table (benchmarks/results_file.py), met when every one
is >= ``--target`` (a rate):

    python benchmarks/bench_expert.py --episodes 100 --presets default --record objects/expert-cube-default \
        --target 0.85
"""

from __future__ import annotations

import argparse
import collections
import itertools
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_file, also when loaded by path
import numpy as np
import results_file

from rlgrasp.envs import PandaGraspEnv, ScriptedExpert, expert_for
from rlgrasp.envs.experts import flat_observation
from rlgrasp.envs.robot_spec import spec_from_file
from rlgrasp.envs.tasks import TASKS
from rlgrasp.evaluation.outcomes import failure_reason as classify
from rlgrasp.stats import wilson_interval


class OffCentreExpert(ScriptedExpert):
    """The scripted expert told the object lies ``offset`` metres further along the pads than it
    does: it grasps that far off the centre, as learned policies do, so the gripper's tolerance is
    measured apart from the policy that makes the offset. (Once lifting, the expert aims at its own
    hand, not the object, so the told offset no longer moves it.)"""

    def __init__(self, *args, offset: float = 0.0, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.offset = offset

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if self.offset:
            # the fingers close along (-sin t, cos t) at hand yaw t; the pads run across it
            obs = flat_observation(obs).copy()
            along_pads = self.offset * np.array([math.cos(self._yaw), math.sin(self._yaw), 0.0])
            obs[self.s["object_minus_grasp"]] += along_pads.astype(obs.dtype)
        return super().__call__(obs)


def failure_reason(infos: list[dict], env=None) -> str:
    last = infos[-1]
    if "goal_distance" in last:  # a goal task
        task = env.unwrapped.task
        if float(last["goal_distance"]) >= task.distance_threshold:
            return "goal not reached"
        if bool(last["grasped"]):
            return "held at the end"
        return "base moved"
    return classify(
        [bool(i["grasped"]) for i in infos],
        [float(i["object_tilt"]) for i in infos],
        infos[-1]["object_extents"],
    )


def run(
    preset: str,
    objects,
    episodes: int,
    ee_yaw: bool,
    robot: str = "panda",
    first_seed: int = 0,
    collision_model: str = "mesh",
    offset: float = 0.0,
    task: str = "lift",
) -> dict:
    arm = spec_from_file(robot) if robot.endswith((".yaml", ".yml")) else robot
    env = PandaGraspEnv(
        randomization=preset,
        objects=objects,
        robot=arm,
        task=task,
        control={"ee_yaw": ee_yaw},
        sim={"collision_model": collision_model},
    )
    expert = OffCentreExpert.for_env(env, offset=offset) if task == "lift" else expert_for(env)
    successes, steps_to_success, reasons, failed = 0, [], collections.Counter(), []
    for seed in range(first_seed, first_seed + episodes):
        obs, info = env.reset(seed=seed)
        expert.reset()
        infos, first = [info], None
        for step in range(env.sim.max_episode_steps):
            obs, _, _, _, info = env.step(expert(obs))
            infos.append(info)
            if info["is_success"] and first is None:
                first = step + 1
        if info["is_success"]:
            successes += 1
        else:
            reason = failure_reason(infos, env)
            reasons[reason] += 1
            failed.append(f"{seed}:{info['object']}:{reason}")
        if first is not None:
            steps_to_success.append(first)
    env.close()
    mean_steps = sum(steps_to_success) / max(len(steps_to_success), 1)
    return {"successes": successes, "mean_steps": mean_steps, "reasons": reasons, "failed": failed}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--presets", nargs="+", default=["none", "default", "wide"])
    parser.add_argument("--objects", nargs="+", default=["cube"], help="object sets, one row each")
    parser.add_argument("--no-yaw", action="store_true", help="keep the hand at yaw 0 (ee_yaw=False)")
    parser.add_argument(
        "--robot",
        nargs="+",
        default=["panda"],
        help="arms, one row each: built-in names or YAML files of a robot config group",
    )
    parser.add_argument(
        "--first-seed",
        type=int,
        default=0,
        help="seeds first-seed.. (a long measurement in parts: their counts add up)",
    )
    parser.add_argument("--list-failures", action="store_true", help="print seed:object:reason")
    parser.add_argument(
        "--collision-model",
        default="mesh",
        choices=["mesh", "primitive"],
        help="the arm's collision shapes (rlgrasp.envs.collision_model)",
    )
    parser.add_argument(
        "--offset",
        type=float,
        default=0.0,
        help="metres off the object's centre along the pads that the expert grasps (0: at the centre)",
    )
    parser.add_argument("--task", default="lift", choices=list(TASKS), help="whose expert to measure")
    results_file.add_options(parser)
    parser.add_argument("--target", type=float, help="with --record: the success rate every row must reach")
    args = parser.parse_args()
    if args.offset and args.task != "lift":
        parser.error("--offset measures the lift expert's grasp: use it with --task lift")
    cases = []
    print(f"task {args.task}")
    print(
        f"{'robot':<11}{'objects':<20}{'preset':<9}{'success at end':>16}{'95% Wilson':>16}"
        f"{'steps to success':>18}  failure reasons"
    )
    for robot, objects, preset in itertools.product(args.robot, args.objects, args.presets):
        r = run(
            preset,
            objects,
            args.episodes,
            not args.no_yaw,
            robot,
            args.first_seed,
            args.collision_model,
            args.offset,
            args.task,
        )
        low, high = wilson_interval(r["successes"], args.episodes)
        reasons = ", ".join(f"{k} {v}" for k, v in r["reasons"].most_common()) or "-"
        print(
            f"{robot:<11}{objects:<20}{preset:<9}{r['successes']:>9d}/{args.episodes:<6d}"
            f"{f'[{low:.2f}, {high:.2f}]':>16}{r['mean_steps']:>18.1f}  {reasons}",
            flush=True,
        )
        if args.list_failures:
            print("   ", " ".join(r["failed"]))
        cases.append((robot, objects, preset, r["successes"], args.episodes))
    if args.record:
        met = (
            "see page"
            if args.target is None
            else results_file.met_of([s >= args.target * n - 1e-9 for *_, s, n in cases])
        )
        results_file.record(*args.record, record_text(cases), met, load=args.record_load)


def record_text(cases: list[tuple[str, str, str, int, int]]) -> str:
    """The results table's ``measured`` cell from (robot, objects, preset, successes, episodes):
    successes per preset, grouped by arm and object set, e.g. "panda cube: none 100/100, default 98/100"."""
    groups: dict[tuple[str, str], list[str]] = {}
    for robot, objects, preset, successes, episodes in cases:
        groups.setdefault((robot, objects), []).append(f"{preset} {successes}/{episodes}")
    return "; ".join(f"{robot} {objects}: {', '.join(parts)}" for (robot, objects), parts in groups.items())


if __name__ == "__main__":
    main()
