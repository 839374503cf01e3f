# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # rlgrasp in a notebook: from a PyBullet arm to a trained grasp
#
# The path of the PyBullet tutorial rlgrasp grew from, one step at a time: the KUKA iiwa in plain
# PyBullet, the Panda through rlgrasp's pieces, the gymnasium env, a tiny PPO run and the shipped
# policy, sparse rewards, randomization, and parallel workers. It is the notebook form of
# [docs/tutorial.md](../docs/tutorial.md), whose steps are `examples/tutorial.py`.
#
# Install with `pip install -e ".[notebook]"`, open with `pip install jupyterlab && jupyter lab`.
# It writes only under `outputs/notebook/` (or `$RLGRASP_NOTEBOOK_OUT`).
#
# This notebook is generated: edit `examples/notebook.py`, then, from the repository's root,
#
# ```bash
# jupytext --to ipynb examples/notebook.py -o examples/tutorial.ipynb
# jupyter execute --inplace examples/tutorial.ipynb
# ```
#
# (`tests/test_notebook.py` fails while the two differ).

# %% [markdown]
# First the imports every section shares, and the working directory: the repository's root, where
# `policies/` holds the shipped policies.

# %%
import os
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import rlgrasp


def repository_root(start: Path) -> Path:
    """The first folder at or above ``start`` that holds the shipped policies, else the checkout
    rlgrasp is imported from."""
    for folder in (start, *start.parents, Path(rlgrasp.__file__).resolve().parents[1]):
        if (folder / "policies" / "grasp_ppo.pt").is_file():
            return folder
    raise FileNotFoundError(
        f"no policies/grasp_ppo.pt at or above {start}: open the notebook in rlgrasp's checkout"
    )


def fresh(name: str) -> Path:
    """A folder under OUT that does not exist yet: each cell that writes can be run again."""
    path, n = OUT / name, 1
    while path.exists():
        path, n = OUT / f"{name}_{n}", n + 1
    return path


def show(images: list[np.ndarray], titles: list[str]) -> None:
    """Images side by side, without axes."""
    fig, axes = plt.subplots(1, len(images), figsize=(4 * len(images), 3.2), squeeze=False)
    for ax, image, title in zip(axes[0], images, titles):
        ax.imshow(image)
        ax.set_title(title)
        ax.axis("off")
    fig.tight_layout()
    plt.show()


os.chdir(repository_root(Path.cwd()))
OUT = Path(os.environ.get("RLGRASP_NOTEBOOK_OUT", "outputs/notebook"))
OUT.mkdir(parents=True, exist_ok=True)
# tqdm (installed with the sweep extra) asks for ipywidgets in a notebook; nothing here shows a progress bar.
warnings.filterwarnings("ignore", message="IProgress not found")
print("writing to", OUT)

# %% [markdown]
# ## 1. PyBullet itself: the KUKA iiwa
#
# A physics client in DIRECT mode (no window: any process, as fast as the CPU allows), the ground
# and the KUKA iiwa from the models that ship with PyBullet (`pybullet_data`). `BulletClient` is
# PyBullet's own wrapper that binds every function to one client; PyBullet prints `argv[0]=` each
# time a client connects.

# %%
import pybullet
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

p = BulletClient(connection_mode=pybullet.DIRECT)
p.setAdditionalSearchPath(pybullet_data.getDataPath())
p.setGravity(0, 0, -9.81)
plane = p.loadURDF("plane.urdf")
kuka = p.loadURDF("kuka_iiwa/model.urdf", useFixedBase=True)
joints = range(p.getNumJoints(kuka))
for j in joints:
    info = p.getJointInfo(kuka, j)
    print(j, info[1].decode(), "limits", np.round(info[8:10], 2))
assert p.getNumJoints(kuka) == 7

# %% [markdown]
# Each step advances the world by 1/240 s. PyBullet's default velocity motors hold a loaded arm's
# joints still, so a second of gravity leaves it where it was; a position controller per joint then
# drives the joints to target angles over two seconds.

# %%
start = np.array([p.getJointState(kuka, j)[0] for j in joints])
for _ in range(240):
    p.stepSimulation()
moved = np.array([p.getJointState(kuka, j)[0] for j in joints]) - start
print("a second of gravity moved the joints by at most (rad)", np.abs(moved).max().round(4))

target = [0.3, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0]
p.setJointMotorControlArray(kuka, list(joints), pybullet.POSITION_CONTROL, targetPositions=target)
for _ in range(480):
    p.stepSimulation()
reached = np.array([p.getJointState(kuka, j)[0] for j in joints])
print("joint control: largest error (rad)", np.abs(reached - target).max().round(4))
assert np.abs(reached - target).max() < 0.02

# %% [markdown]
# Inverse kinematics asks for joint angles that put a link (here the flange, link 6) at a point with
# a given orientation; the position controllers then drive the arm there.

# %%
goal = np.array([0.5, 0.2, 0.4])
down = p.getQuaternionFromEuler([0, np.pi, 0])
q = p.calculateInverseKinematics(kuka, 6, goal, down, maxNumIterations=200, residualThreshold=1e-5)
p.setJointMotorControlArray(kuka, list(joints), pybullet.POSITION_CONTROL, targetPositions=q)
for _ in range(480):
    p.stepSimulation()
flange = np.array(p.getLinkState(kuka, 6, computeForwardKinematics=True)[4])
print("IK: flange at", flange.round(3), "error (m)", np.linalg.norm(flange - goal).round(4))
assert np.linalg.norm(flange - goal) < 0.01

# %% [markdown]
# A camera is a view matrix (where it looks from) and a projection (its lens); `getCameraImage`
# renders through them, here with the CPU renderer that needs no display.

# %%
view = p.computeViewMatrixFromYawPitchRoll(
    [0.2, 0, 0.4], distance=1.6, yaw=50, pitch=-25, roll=0, upAxisIndex=2
)
projection = p.computeProjectionMatrixFOV(fov=60, aspect=4 / 3, nearVal=0.05, farVal=5)
width, height, rgba, depth, segmentation = p.getCameraImage(
    320, 240, view, projection, renderer=pybullet.ER_TINY_RENDERER
)
kuka_image = np.reshape(rgba, (height, width, 4))[:, :, :3].astype(np.uint8)
show([kuka_image], ["the KUKA iiwa at its IK target"])
p.disconnect()

# %% [markdown]
# ## 2. The Panda through rlgrasp's pieces
#
# `Scene` owns one DIRECT client with the ground; `make_robot` loads an arm rlgrasp knows (`panda`,
# `kuka_iiwa`, `xarm6`, or one of your own) and finds its arm joints, fingers and grasp frame. Its
# `inverse_kinematics` aims the point between the fingertips, gripper pointing down. PyBullet's solver
# starts from the arm's current pose and stops after a few iterations, so its first answer can land
# short; asked again from where the arm landed, it closes in.

# %%
from rlgrasp.envs.robot import ROBOTS, make_robot
from rlgrasp.envs.scene import Scene

world = Scene()
c = world.client
c.setGravity(0, 0, -9.81)
panda = make_robot("panda", c)
print("arm joints", panda.arm, "fingers", panda.fingers, "- the arms rlgrasp ships:", list(ROBOTS))
panda.reset(panda.neutral_pose)
panda.use_position_control()

goal = np.array([0.55, 0.1, 0.2])
panda.command_fingers(0.04)
for attempt in range(1, 4):
    panda.command_arm(panda.inverse_kinematics(goal))
    for _ in range(240):
        c.stepSimulation()
    position, velocity = panda.grasp_point()
    print(
        f"IK, round {attempt}: grasp point {position.round(3)}, error {np.linalg.norm(position - goal):.4f} m"
    )
panda_image = world.viewer_image(width=320, height=240, distance=1.3, yaw=50, pitch=-25)
show([panda_image], ["the Panda, fingers open, at its IK target"])
world.close()
assert np.linalg.norm(position - goal) < 0.01

# %% [markdown]
# ## 3. The gymnasium env
#
# `import rlgrasp` registers `rlgrasp/PandaGrasp-v0` (the class is `rlgrasp.envs.GraspEnv`): the
# scene, the arm, the cube and its randomization, the reward and the success test behind `reset`
# and `step`. gymnasium's checker tests its spaces, seeding and determinism (and warns that the
# observation box is unbounded).

# %%
import gymnasium as gym
from gymnasium.utils.env_checker import check_env

env = gym.make(rlgrasp.ENV_ID, control={"mode": "ee_delta"}, render_mode="rgb_array")
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    check_env(env.unwrapped, skip_render_check=True)
for w in caught:
    print("check_env:", w.message)
print("observation", env.observation_space.shape, "parts", list(env.unwrapped.obs_slices))
print("action", env.action_space)
obs, info = env.reset(seed=0)
assert env.observation_space.contains(obs)

# %% [markdown]
# The scripted expert acts through the same API (`ee_delta`: steps of the grasp point, through IK);
# three frames of its episode, rendered by the env's `rgb_array` mode.

# %%
from rlgrasp.envs import ScriptedExpert

expert = ScriptedExpert.for_env(env)
frames, episode_return = [env.render()], 0.0
for step in range(50):
    obs, reward, terminated, truncated, info = env.step(expert(obs))
    episode_return += reward
    if step in (15, 49):
        frames.append(env.render())
    if terminated or truncated:
        break
print(f"the scripted expert: return {episode_return:.2f}, success {info['is_success']}")
show(frames, ["reset", "after 16 steps", "after 50 steps"])
env.close()
assert info["is_success"]

# %% [markdown]
# ## 4. Training, and the shipped policy
#
# `compose_train` builds the config `python scripts/train.py experiment=smoke` would, and `train`
# runs it: two worker processes collect, PPO updates, checkpoints and TensorBoard events land in the
# run folder. The smoke budget (2,048 frames) checks that everything runs, not that the arm learns.

# %%
from rlgrasp.compose import compose_eval, compose_train
from rlgrasp.train.loop import train

run = fresh("smoke")
cfg = compose_train(["experiment=smoke", f"paths.output_dir={run}", "seed=0"])
final_success = train(cfg)
print("final evaluation success", final_success, "- curves: tensorboard --logdir", run)
assert (run / "checkpoints").is_dir() and 0.0 <= final_success <= 1.0

# %% [markdown]
# A real run (`python scripts/train.py experiment=grasp_ppo`) takes minutes; `policies/grasp_ppo.pt`
# is one, shipped. `evaluate` is `python scripts/evaluate.py`: seeded episodes, success with a 95%
# Wilson interval, and files per episode. Its console lines are muted here and its files read instead.

# %%
import contextlib
import csv
import io
import logging

from rlgrasp.evaluation.cli import evaluate

logging.getLogger("rlgrasp.eval").setLevel(logging.WARNING)
with contextlib.redirect_stdout(io.StringIO()):
    metrics = evaluate(
        compose_eval(
            [
                "ckpt=policies/grasp_ppo.pt",
                "episodes=8",
                "video=false",
                "plots=false",
                f"out_dir={fresh('eval_grasp_ppo')}",
            ]
        )
    )
evaluated = Path(metrics["output_dir"])
print("files:", sorted(path.name for path in evaluated.iterdir()))
with open(evaluated / "episodes.csv") as f:
    episodes = list(csv.DictReader(f))
for e in episodes:
    print(f"seed {e['seed']}: {e['outcome']}, return {float(e['return']):.1f}")
s = metrics["success_at_end"]
low, high = s["ci95"]
print(f"the shipped policy: success {s['successes']}/{s['episodes']}, 95% Wilson [{low:.2f}, {high:.2f}]")
assert s["successes"] >= s["episodes"] / 2

# %% [markdown]
# The same policy by hand: `policy_from_checkpoint` gives the actor (its observation normalizer
# inside), which reads a tensordict and writes an action. In the env it was trained in (the cube,
# `joint_delta` control, `default` randomization) it replays evaluate's episode of the same seed.

# %%
import torch
from tensordict import TensorDict

from rlgrasp.envs import GraspEnv
from rlgrasp.policy_file import policy_from_checkpoint

policy = policy_from_checkpoint("policies/grasp_ppo.pt")
env = GraspEnv(control={"mode": "joint_delta"}, render_mode="rgb_array")
seed = 1
obs, info = env.reset(seed=seed)
frames = [env.render()]
for step in range(env.sim.max_episode_steps):
    with torch.no_grad():
        td = policy(TensorDict({"observation": torch.as_tensor(obs).unsqueeze(0)}, batch_size=[1]))
    obs, reward, terminated, truncated, info = env.step(td["action"][0].numpy())
    if step in (15, 49):
        frames.append(env.render())
show(frames, ["reset", "after 16 steps", "after 50 steps"])
env.close()
lifted = {int(e["seed"]): e["success_at_end"] == "1" for e in episodes}
print(f"seed {seed}: lifted {bool(info['is_success'])} here, {lifted[seed]} in evaluate's episodes.csv")
assert bool(info["is_success"]) == lifted[seed]

# %% [markdown]
# ## 5. Sparse rewards
#
# With `reward: sparse` the env pays only success, so a policy that explores at random sees nothing
# but zeros, and PPO alone has nothing to learn from.

# %%
env = GraspEnv(task={"name": "lift", "reward": "sparse"}, control={"mode": "ee_delta"})
env.reset(seed=0)
env.action_space.seed(0)
rewards = [env.step(env.action_space.sample())[1] for _ in range(env.sim.max_episode_steps)]
print("sparse rewards of a random episode:", sorted({float(r) for r in rewards}))
env.close()
assert not any(rewards)

# %% [markdown]
# One remedy is demonstrations: record the scripted expert's successful episodes (as
# `python scripts/demos.py` does), clone them by behaviour cloning, then let PPO keep a decaying
# imitation term (`experiment=grasp_sparse_demos`). A tiny run, in this process (`collector=single`):

# %%
from rlgrasp.compose import compose_config
from rlgrasp.demos.cli import record_demos

demos = fresh("demos")
summary = record_demos(compose_config("demos", ["episodes=5", f"out={demos}", "workers=1"]))
print("demonstrations: expert success", summary["success_rate"], "- frames kept", summary["frames"])

sparse_run = fresh("sparse")
cfg = compose_train(
    [
        "experiment=grasp_sparse_demos",
        f"algo.demos={demos / 'demos'}",
        f"paths.output_dir={sparse_run}",
        "collector=single",
        "collector.envs_per_worker=2",
        "collector.steps_per_env=128",
        "total_frames=256",
        "algo.optim.minibatch_size=128",
        "algo.pretrain.epochs=100",
        "eval.interval_frames=0",
        "eval.final_episodes=8",
        "eval.num_envs=4",
    ]
)
sparse_success = train(cfg)
print("sparse reward, with demonstrations: final evaluation success", sparse_success)
assert summary["frames"] > 0 and (sparse_run / "checkpoints").is_dir()

# %% [markdown]
# The other remedy is curiosity, an intrinsic reward for states the policy has not seen
# (`experiment=grasp_sparse_rnd`); docs/sparse.md has both, measured over minutes and seeds.

# %% [markdown]
# ## 6. Randomization
#
# Every episode draws the cube's pose, size, mass and friction, the arm's gains, gravity, noise and
# delay from the ranges of a preset: `none`, `default` (what training uses) or `wide` (1.8 times as
# wide). The scripted expert, four episodes under each of the two: `wide` includes cubes this gripper
# cannot lift (docs/adr.md), so a policy is judged on the ranges it will meet.

# %%
from rlgrasp.envs import PRESETS

print(
    "wide:", {k: (round(r.low, 3), round(r.high, 3)) for k, r in PRESETS["wide"].items() if r.low != r.high}
)
successes = {}
for preset in ("default", "wide"):
    env = GraspEnv(randomization=preset, control={"mode": "ee_delta"})
    expert = ScriptedExpert.for_env(env)
    successes[preset] = 0
    for seed in range(4):
        obs, info = env.reset(seed=seed)
        expert.reset()
        draws = info["randomization"]
        for _ in range(env.sim.max_episode_steps):
            obs, reward, terminated, truncated, info = env.step(expert(obs))
        successes[preset] += bool(info["is_success"])
        size, mass, force = (draws[k] for k in ("object_size_scale", "object_mass", "finger_force"))
        outcome = "lifted" if info["is_success"] else "not lifted"
        print(
            f"{preset}, seed {seed}: size x{size:.2f}, mass {mass:.3f} kg, fingers {force:.0f} N: {outcome}"
        )
    env.close()
print("the expert's successes of 4:", successes)
assert successes["default"] >= 3

# %% [markdown]
# What a camera sees can be randomized too (`sim.visual`): colours, textures and light per episode.
# Two seeds, side by side:

# %%
env = GraspEnv(randomization="wide", sim={"visual": "default"}, render_mode="rgb_array")
scenes = []
for seed in (1, 2):
    env.reset(seed=seed)
    scenes.append(env.render())
env.close()
show(scenes, ["seed 1", "seed 2"])
assert not np.array_equal(scenes[0], scenes[1])

# %% [markdown]
# ## 7. DIRECT mode and parallel workers
#
# Every env here runs PyBullet in DIRECT mode, without a window, so any process can hold several.
# PyBullet steps one env at a time on one core; worker processes step several at once and pay for it
# in messages: gymnasium's two vector envs show the trade on this machine (frames: env steps). The
# workers are spawned (fresh interpreters, as rlgrasp's collector starts them) and build their envs
# from a library class (`functools.partial(GraspEnv, ...)`): a spawned worker cannot import a
# function defined in a notebook.

# %%
import functools
import time

from gymnasium.vector import AsyncVectorEnv, SyncVectorEnv

make = functools.partial(GraspEnv, control={"mode": "joint_delta"})
rates = {}
for name, vector, options in (
    ("in this process", SyncVectorEnv, {}),
    ("two worker processes", AsyncVectorEnv, {"context": "spawn"}),
):
    envs = vector([make, make], **options)
    obs, info = envs.reset(seed=0)
    start = time.perf_counter()
    for _ in range(100):
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
    rates[name] = 2 * 100 / (time.perf_counter() - start)
    envs.close()
    print(f"{name}: {rates[name]:.0f} frames/s")
assert obs.shape[0] == 2 and all(rate > 0 for rate in rates.values())

# %% [markdown]
# rlgrasp's collector (section 4) goes further: worker processes that each step a batch of envs,
# collection overlapped with the PPO update (`collector.num_workers`, `collector.envs_per_worker`,
# Ray or SLURM across machines: docs/training.md, docs/scaling.md).

# %% [markdown]
# Where next: docs/tutorial.md (the same path as a script, `examples/tutorial.py`), docs/training.md,
# docs/environment.md and docs/evaluation.md. `python scripts/train.py experiment=grasp_ppo` trains a
# policy like the shipped one.
