"""The tutorial of docs/tutorial.md, every step as it is shown there (the page includes this file's
marked sections, so the two cannot drift): a PyBullet scene, joint and IK control of the Panda, the
gymnasium env, a smoke training with its evaluation, a sparse reward and demonstrations,
randomization and a held-out evaluation, subprocess workers.

    python examples/tutorial.py                 # every step, a few minutes on a laptop
    python examples/tutorial.py scene control   # some steps (names below, in STEPS)

Run it from the repository's root (it reads policies/). What it writes goes under
outputs/tutorial/, or RLGRASP_TUTORIAL_OUT. tests/test_tutorial.py runs it.
"""

from __future__ import annotations

import sys


def scene() -> None:
    # --8<-- [start:scene]
    from rlgrasp.envs.robot import ROBOTS, make_robot
    from rlgrasp.envs.scene import Scene

    world = Scene()  # one private PyBullet client in DIRECT mode (Scene(gui=True): a window)
    c = world.client  # a BulletClient: every pybullet function, bound to this client
    c.setGravity(0, 0, -9.81)
    panda = make_robot("panda", c)  # loads franka_panda/panda.urdf from pybullet_data
    kinds = {0: "revolute", 1: "prismatic", 4: "fixed"}
    for j in range(c.getNumJoints(panda.body)):
        info = c.getJointInfo(panda.body, j)
        print(j, info[1].decode(), kinds.get(info[2], info[2]), "limits", info[8:10])
    print("arm joints", panda.arm, "fingers", panda.fingers, "dof", panda.arm_dof)
    print("the arms rlgrasp ships:", list(ROBOTS))
    # --8<-- [end:scene]
    world.close()


def control() -> None:
    # --8<-- [start:control]
    import numpy as np

    from rlgrasp.envs.robot import make_robot
    from rlgrasp.envs.scene import Scene

    world = Scene()
    c = world.client
    c.setGravity(0, 0, -9.81)
    panda = make_robot("panda", c)
    panda.reset(panda.neutral_pose)  # teleport the joints: no physics
    panda.use_position_control()

    # Joint control: a target angle per joint, PD motors drive them there.
    target = np.array(panda.neutral_pose) + np.array([0.4, -0.3, 0.0, 0.3, 0.0, 0.0, 0.5])  # up and turned
    panda.command_arm(target)
    panda.command_fingers(0.04)  # finger opening in metres
    for _ in range(480):  # two seconds at PyBullet's 240 Hz
        c.stepSimulation()
    q, qd, width = panda.joint_state()
    print("joint control: largest error (rad)", np.abs(q - target).max().round(4), "fingers", round(width, 3))
    # (a target that drives the hand into the ground or the table stops short of it: physics, not a bug)

    # Inverse kinematics: a point for the grasp frame, gripper pointing down.
    goal = np.array([0.5, 0.1, 0.25])
    panda.command_arm(panda.inverse_kinematics(goal))
    for _ in range(480):
        c.stepSimulation()
    position, velocity = panda.grasp_point()
    print("IK: grasp point", position.round(3), "error (m)", np.linalg.norm(position - goal).round(4))
    # --8<-- [end:control]
    world.close()


def env() -> None:
    # --8<-- [start:env]
    from gymnasium.utils.env_checker import check_env

    from rlgrasp.envs import GraspEnv, ScriptedExpert

    env = GraspEnv(control={"mode": "ee_delta"})  # the cube, `default` randomization, 50 steps an episode
    check_env(env.unwrapped, skip_render_check=True)  # gymnasium's checker: spaces, seeding, determinism
    print("observation", env.observation_space.shape, "parts", list(env.obs_slices))
    print("action", env.action_space)

    expert = ScriptedExpert.for_env(env)  # the grasp the arm's description sets
    obs, info = env.reset(seed=0)
    episode_return, steps = 0.0, 0
    for _ in range(env.sim.max_episode_steps):
        obs, reward, terminated, truncated, info = env.step(expert(obs))
        episode_return, steps = episode_return + reward, steps + 1
        if terminated or truncated:
            break
    print(f"the scripted expert: {steps} steps, return {episode_return:.2f}, success {info['is_success']}")
    env.close()
    # --8<-- [end:env]


def train_and_evaluate(out: str) -> None:
    # --8<-- [start:train]
    from pathlib import Path

    from rlgrasp.compose import compose_eval, compose_train
    from rlgrasp.evaluation.cli import evaluate
    from rlgrasp.train.loop import train

    run = Path(out) / "smoke"
    # The config `python scripts/train.py experiment=smoke` builds: 2,048 frames, two worker processes.
    cfg = compose_train(["experiment=smoke", f"paths.output_dir={run}", "seed=0"])
    final_success = train(cfg)
    print("final evaluation success", final_success, "- TensorBoard: tensorboard --logdir", run)

    # Evaluate the run's best checkpoint on 20 seeded episodes: success with a 95% Wilson interval.
    metrics = evaluate(
        compose_eval([f"ckpt={run}", "episodes=20", "video=false", "plots=false", f"out_dir={run / 'eval'}"])
    )
    s = metrics["success_at_end"]  # also in <run>/eval/metrics.json, beside episodes.csv and summary.md
    print(f"success {s['rate']:.2f}, 95% Wilson [{s['ci95'][0]:.2f}, {s['ci95'][1]:.2f}]")
    # --8<-- [end:train]


def sparse(out: str) -> None:
    # --8<-- [start:sparse]
    from pathlib import Path

    import numpy as np

    from rlgrasp.compose import compose_config, compose_train
    from rlgrasp.demos.cli import record_demos
    from rlgrasp.envs import GraspEnv
    from rlgrasp.train.loop import train

    # A sparse reward pays only success: random actions see nothing but zeros.
    env = GraspEnv(task={"name": "lift", "reward": "sparse"}, control={"mode": "ee_delta"})
    env.reset(seed=0)
    rewards = [env.step(env.action_space.sample())[1] for _ in range(env.sim.max_episode_steps)]
    print("sparse rewards of a random episode:", sorted(set(np.round(rewards, 3))))
    env.close()

    # The scripted expert's successful episodes (`python scripts/demos.py episodes=10 out=...`) ...
    demos = Path(out) / "demos"
    summary = record_demos(compose_config("demos", ["episodes=10", f"out={demos}", "workers=1"]))
    print("demonstrations: expert success", summary["success_rate"], "frames kept", summary["frames"])

    # ... pre-train the policy by behaviour cloning, then PPO keeps an imitation term (DAPG).
    cfg = compose_train(
        [
            "experiment=grasp_sparse_demos",
            f"algo.demos={demos / 'demos'}",
            f"paths.output_dir={Path(out) / 'sparse'}",
            "total_frames=2048",
            "collector.envs_per_worker=2",
            "collector.steps_per_env=256",
            "eval.interval_frames=1024",
            "eval.episodes=4",
            "eval.final_episodes=8",
            "eval.num_envs=4",
            "algo.pretrain.epochs=100",
        ]
    )
    print("with demonstrations, final evaluation success", train(cfg))
    # --8<-- [end:sparse]


def randomization(out: str) -> None:
    # --8<-- [start:randomization]
    from pathlib import Path

    from rlgrasp.compose import compose_eval
    from rlgrasp.envs import PRESETS, GraspEnv
    from rlgrasp.evaluation.cli import evaluate

    for name, ranges in PRESETS.items():
        print(name, {k: (round(r.low, 3), round(r.high, 3)) for k, r in ranges.items() if r.low != r.high})

    env = GraspEnv(randomization="wide")  # every range of `default`, 1.8x as wide
    obs, info = env.reset(seed=1)
    print("this episode's draws:", {k: round(float(v), 3) for k, v in info["randomization"].items()})
    env.close()

    # A held-out evaluation: the shipped objects policy on 100 meshes it never saw (10 episodes here).
    metrics = evaluate(
        compose_eval(
            [
                "ckpt=policies/grasp_objects_ppo.pt",
                "objects=random_urdfs_test",
                "episodes=10",
                "video=false",
                "plots=false",
                f"out_dir={Path(out) / 'heldout'}",
            ]
        )
    )
    s = metrics["success_at_end"]
    print(f"held-out meshes: success {s['rate']:.2f}, 95% Wilson [{s['ci95'][0]:.2f}, {s['ci95'][1]:.2f}]")
    # --8<-- [end:randomization]


def workers() -> None:
    # --8<-- [start:workers]
    import functools
    import time

    from gymnasium.vector import AsyncVectorEnv, SyncVectorEnv

    from rlgrasp.envs import GraspEnv

    make = functools.partial(GraspEnv, control={"mode": "joint_delta"})  # picklable: it travels to a worker
    for vector in (SyncVectorEnv, AsyncVectorEnv):  # all in this process / one process per env
        envs = vector([make, make])
        envs.reset(seed=0)
        start = time.perf_counter()
        for _ in range(100):
            envs.step(envs.action_space.sample())
        print(f"{vector.__name__}: {2 * 100 / (time.perf_counter() - start):.0f} env steps/s")
        envs.close()
    # --8<-- [end:workers]


STEPS = {
    "scene": lambda out: scene(),
    "control": lambda out: control(),
    "env": lambda out: env(),
    "train": train_and_evaluate,
    "sparse": sparse,
    "randomization": randomization,
    "workers": lambda out: workers(),
}


def main(argv: list[str]) -> None:
    import os

    out = os.environ.get("RLGRASP_TUTORIAL_OUT", "outputs/tutorial")
    names = argv or list(STEPS)
    unknown = [n for n in names if n not in STEPS]
    if unknown:
        sys.exit(f"unknown step(s) {', '.join(unknown)}; steps: {', '.join(STEPS)}")
    for name in names:
        print(f"--- {name}")
        STEPS[name](out)


if __name__ == "__main__":  # worker processes are spawned: they import this file, and must not rerun it
    main(sys.argv[1:])
