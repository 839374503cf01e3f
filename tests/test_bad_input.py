"""Bad input to every entry point: each gives one line naming the key or file and what is allowed, a
non-zero exit code, no traceback, and leaves nothing behind (no run, evaluation or export folder).
The cases run the real entry points (Hydra and argparse included) in-process: scripts/train.py,
scripts/evaluate.py (rlgrasp-eval), scripts/export.py, scripts/enjoy.py (without a display: the
checks come before the display's), scripts/sweep.py, scripts/demos.py (rlgrasp-demos), rlgrasp-demo and
scripts/report.py (rlgrasp-report).

``python -m tests.test_bad_input`` (from the repository root) prints the bad-input table of the docs
from these cases.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import pickle
import socket
import tempfile
from pathlib import Path

import pybullet_data
import pytest
import torch
from omegaconf import OmegaConf

from rlgrasp.compose import compose_train
from rlgrasp.policy_file import CHECKPOINT_FORMAT
from rlgrasp.train.loop import Trainer
from rlgrasp.train.validate import validate_train
from rlgrasp.utils import markdown_table
from tests.helpers import bad_input_files, demo_files, our_lines, run_entry

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ["experiment=smoke", "logger=none"]
#: Each entry point's command before a case's arguments (placeholders filled by _fill).
BASE = {
    "train": [*SMOKE, "paths.root_dir={root}"],
    "train_sac": ["experiment=grasp_sac", "logger=none", "paths.root_dir={root}"],
    "eval": ["ckpt={run}", "ckpt_kind=last", "episodes=2", "video=false", "plots=false"],
    "export": ["ckpt={run}", "ckpt_kind=last", "verify_obs=20"],
    "enjoy": ["ckpt={run}", "ckpt_kind=last"],
    "sweep": ["experiment=smoke", "sweep.root_dir={root}/sweeps"],
    "demo": ["--out", "{root}/demo", "--episodes", "1"],
    "demos": ["out={root}/demos_out", "episodes=1", "workers=1"],
    "report": ["{run}", "--out", "{root}/report"],
}
COMMANDS = {
    "train": "scripts/train.py experiment=smoke logger=none",
    "train_sac": "scripts/train.py experiment=grasp_sac logger=none",
    "eval": "rlgrasp-eval ckpt=<run> ckpt_kind=last episodes=2 video=false plots=false",
    "export": "rlgrasp-export ckpt=<run> ckpt_kind=last verify_obs=20",
    "enjoy": "rlgrasp-enjoy ckpt=<run> ckpt_kind=last (no display)",
    "sweep": "rlgrasp-sweep experiment=smoke",
    "demo": "rlgrasp-demo --out <dir> --episodes 1",
    "demos": "rlgrasp-demos out=<dir> episodes=1 workers=1",
    "report": "rlgrasp-report <run> --out <dir>",
}


def _make_run(root: Path) -> Path:
    """A run directory as a launch leaves it (its ``.hydra/config.yaml``) holding one real smoke
    checkpoint (built without starting workers)."""
    run = root / "outputs" / "train" / "smoke" / "done_run"
    if not (run / "checkpoints" / "last.pt").exists():
        cfg = compose_train([*SMOKE, f"paths.output_dir={run}"])
        Trainer(cfg).save()
        (run / ".hydra").mkdir()
        (run / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    return run


def _files(root: Path) -> dict[str, str]:
    """Inputs that are files: a run, an empty dir, a truncated checkpoint, a foreign pickle, a file
    where a folder should be, a mesh that is not one, a file that is no mesh at all."""
    run = _make_run(root)
    empty = root / "empty_run"
    empty.mkdir(exist_ok=True)
    truncated = root / "truncated.pt"
    data = (run / "checkpoints" / "last.pt").read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    foreign = root / "foreign.pt"
    foreign.write_bytes(pickle.dumps({"weights": [1, 2, 3]}))
    unwritable = root / "a_file"
    unwritable.write_text("not a directory")
    notamesh = root / "notamesh.obj"
    notamesh.write_text("this is not a mesh\n")
    notes = root / "notes.txt"
    notes.write_text("not a model")
    demos = demo_files(root)  # demonstrations of another control mode, of no episode, of another view
    return {
        "run": str(run),
        "empty": str(empty),
        "truncated": str(truncated),
        "foreign": str(foreign),
        "unwritable": str(unwritable / "out"),
        "notamesh": str(notamesh),
        "notes": str(notes),
        **bad_input_files(root),  # camera checkpoints: student, orphan, mismatched; the teacher
        **demos,
        **_more_files(root, run, Path(demos["empty_demos"])),
    }


def _more_files(root: Path, run: Path, demos: Path) -> dict[str, str]:
    """A checkpoint of a newer format, demonstrations without their frames, a flat mesh, a closed port."""
    newer = root / "newer.pt"
    if not newer.exists():
        state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
        torch.save({**state, "format": CHECKPOINT_FORMAT + 1}, newer)
    frameless = root / "frameless_demos" / "demos"
    frameless.mkdir(parents=True, exist_ok=True)
    meta = (demos / "demos.json").read_text().replace('"kept": 0', '"kept": 3')
    (frameless / "demos.json").write_text(meta)
    flat = root / "flat.obj"  # a square: four vertices, two faces, on the plane z = 0
    flat.write_text("v 0 0 0\nv 0.03 0 0\nv 0.03 0.03 0\nv 0 0.03 0\nf 1 2 3\nf 1 3 4\n")
    with socket.socket() as sock:  # a port nothing listens on (bound, then released)
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return {
        **_received_files(root, run),
        "newer": str(newer),
        "frameless_demos": str(frameless),
        "flat": str(flat),
        "closed_port": str(port),
    }


def _received_files(root: Path, run: Path) -> dict[str, str]:
    """Checkpoints someone could send that used to end in a traceback: a dict that is no checkpoint,
    NaN weights, an env that is a string, a config that is a list, a spec whose size is a string."""
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    name = next(k for k, v in state["actor"].items() if v.is_floating_point() and v.numel())
    nan = {**state, "actor": {**state["actor"], name: state["actor"][name].flatten().clone()}}
    nan["actor"][name][0] = float("nan")
    nan["actor"][name] = nan["actor"][name].reshape(state["actor"][name].shape)
    made = {
        "not_ckpt": {"weights": torch.zeros(3)},
        "nan_weights": nan,
        "env_string": {**state, "config": {**state["config"], "env": "grasp"}},
        "config_list": {**state, "config": [1]},
        "obs_dim_str": {**state, "spec": {**state["spec"], "obs_dim": "49"}},
    }
    for key, value in made.items():
        if not (root / f"{key}.pt").exists():
            torch.save(value, root / f"{key}.pt")
    return {key: str(root / f"{key}.pt") for key in made}


#: A user's arm (the Panda's model) naming a joint its model does not have.
BAD_ARM = (
    "model:franka_panda/panda.urdf,arm_joints:[panda_joint1,panda_joint9],"
    "grasp_link:panda_grasptarget,fingers:[{joint:panda_finger_joint1,open:0.04}],finger_links:[panda_leftfinger,panda_rightfinger],"
    "neutral_pose:[0,0],max_finger_width:0.08"
)
#: A DAgger depth student of the test's teacher.
DEPTH_STUDENT = ["algo=distill", "cameras=wrist_depth", "model=cnn", "algo.teacher={teacher}"]
# (entry point, what, arguments after BASE (placeholders filled by _fill), a fragment of the one line)
#: What reading a checkpoint of the next format says.
NEWER_FORMAT_LINE = (
    f"has format {CHECKPOINT_FORMAT + 1}, this version reads up to format {CHECKPOINT_FORMAT} "
    "(upgrade rlgrasp)"
)

TRAIN = [
    ("unknown key", ["algo.lrr=1"], "algo.lrr=1: unknown key 'lrr'; algo has _target_, name, loss, optim"),
    (
        "a key of before algo's split by role",
        ["algo.lr=1e-3"],
        "algo.lr=1e-3: unknown key 'lr'; algo has _target_, name, loss, optim, schedule, demos, pretrain, "
        "terms, init_from; algo.lr is algo.optim.lr now",
    ),
    (
        "a part's module of before, in the user's own config",
        ["+algo.terms.x._target_=rlgrasp.train.rnd.RND"],
        "algo.terms.x._target_='rlgrasp.train.rnd.RND' cannot be imported (rlgrasp.train has no 'rnd'); "
        "it moved: write 'rlgrasp.algos.ppo.rnd.RND'",
    ),
    (
        "a string key of before that is a group now",
        [*DEPTH_STUDENT, "algo.augment=colour"],
        "algo.augment is algo.augment.kind now",
    ),
    (
        "a DAgger student's colour augmentation on a depth camera",
        [*DEPTH_STUDENT, "algo.augment.kind=colour"],
        "algo.augment.kind='colour': recolours RGB images; needs a camera with RGB (e.g. cameras=wrist_rgb)",
    ),
    (
        "a DAgger student's overlay on a depth camera",
        [*DEPTH_STUDENT, "algo.augment.overlay=0.5"],
        "algo.augment.overlay=0.5: overlays RGB images; needs a camera with RGB (e.g. cameras=wrist_rgb)",
    ),
    (
        "new key of an open node",
        ["cameras=wrist_depth", "model=cnn", "env.camera.width=48"],
        "env.camera.width=48: unknown key 'width'; env.camera has mount, modality "
        "(a new key of env.camera: +env.camera.width=48)",
    ),
    (
        "wrong type",
        ["algo.optim.lr=abc"],
        "algo.optim.lr=abc: Value 'abc' of type 'str' could not be converted",
    ),
    (
        "unknown group option",
        ["collector=bogus"],
        "collector=bogus: no such option; collector is one of process, ray, single",
    ),
    (
        "unknown objects option",
        ["objects=random_urdfs_tset"],
        "objects=random_urdfs_tset: no such option; objects is one of cube, primitives",
    ),
    ("no frames", ["total_frames=0"], "total_frames=0: must be > 0"),
    ("negative frames", ["total_frames=-5"], "total_frames=-5: must be > 0"),
    ("negative workers", ["collector.num_workers=-1"], "collector.num_workers=-1: must be >= 0"),
    ("no envs per worker", ["collector.envs_per_worker=0"], "collector.envs_per_worker=0: must be >= 1"),
    (
        "minibatch larger than a batch",
        ["algo.optim.minibatch_size=4096"],
        "algo.optim.minibatch_size=4096: must be between 1",
    ),
    ("minibatch 0", ["algo.optim.minibatch_size=0"], "algo.optim.minibatch_size=0: must be between 1"),
    ("no epochs", ["algo.optim.epochs=0"], "algo.optim.epochs=0: must be >= 1"),
    ("zero learning rate", ["algo.optim.lr=0"], "algo.optim.lr=0.0: must be finite and > 0"),
    ("negative learning rate", ["algo.optim.lr=-0.001"], "algo.optim.lr=-0.001: must be finite and > 0"),
    (
        "a zero KL target for the adaptive rate",
        ["algo.schedule.desired_kl=0"],
        "algo.schedule.desired_kl=0.0: must be > 0 or null",
    ),
    ("no substeps", ["env.sim.substeps=0"], "env: sim.substeps must be a positive integer, got 0"),
    ("unknown control mode", ["env.control.mode=fly"], "env: unknown control.mode 'fly'; valid modes"),
    (
        "an env key of before the env took parts",
        ["env.control_mode=joint_delta"],
        "env.control_mode=joint_delta: unknown key 'control_mode'; env has _target_, task, robot, objects, "
        "control, camera, randomization, sim, render_mode; env.control_mode is env.control.mode now",
    ),
    ("no hidden layers", ["model.hidden_sizes=[]"], "model.hidden_sizes=[]: must be a non-empty list"),
    (
        "unknown action distribution",
        ["model.distribution=beta"],
        "model.distribution='beta': must be tanh_normal or normal",
    ),
    ("a camera policy without a camera", ["model=cnn"], "model='cnn': needs a camera (e.g. cameras="),
    ("a state policy with a camera", ["cameras=wrist_depth"], "model='mlp': must be cnn with a camera"),
    ("fine-tuning from nowhere", ["algo.init_from={root}/nowhere.pt"], "nowhere.pt: missing checkpoint"),
    (
        "fine-tuning a camera policy without its camera",
        ["algo.init_from={student}"],
        "env.camera={'mount': 'wrist'",
    ),
    (
        "fine-tuning a policy of another model",
        ["algo.init_from={run}", "model.hidden_sizes=[32]"],
        "its policy does not fit this run's model",
    ),
    (
        "a negative critic warm-up",
        ["algo.schedule.critic_warmup_frames=-1"],
        "algo.schedule.critic_warmup_frames=-1: must be >= 0",
    ),
    (
        "a teacher for a state policy",
        ["algo.terms.teacher.checkpoint={teacher}"],
        "needs a camera (e.g. cameras=wrist_depth)",
    ),
    (
        "a negative teacher weight",
        ["algo.terms.teacher.coeff=-1"],
        "algo.terms.teacher.coeff=-1.0: must be >= 0",
    ),
    (
        "a teacher of another control mode",
        [
            "experiment=grasp_vision_finetune",
            "algo.terms.teacher.checkpoint={teacher}",
            "env.control.mode=ee_delta",
            "algo.init_from=null",
        ],
        "it reads 49 state values, this env's privileged state has 45",
    ),
    (
        "unknown reward weight",
        ["env.task.weights={lfit:3}"],
        "unknown reward term 'lfit' (env.task.weights); terms: reach, grasp, lift, success",
    ),
    (
        "unknown task",
        ["+env.task.name=fly", "~env.task._target_"],
        "unknown task 'fly' (env.task); tasks: lift",
    ),
    (
        "unknown reward term",
        ["env.task.reward={terms: {lfit: {weight: 1}}}"],
        "unknown reward term 'lfit' (env.task.reward.terms); this task's terms: reach, grasp, lift, success",
    ),
    (
        "a term weight that is not finite",
        ["env.task.weights={lift: nan}"],
        "env.task.reward.terms.lift.weight must be a finite number, got nan",
    ),
    (
        "a goal out of the arm's reach",
        ["task=pick_place", "env.task.observation=flat", "env.task.goal_range=[0.5,0.5]"],
        "env.task.goal_range=[0.5, 0.5] puts goals 1.21 m from the arm's base",
    ),
    (
        "a goal task's Dict observation with a learner that reads one vector",
        ["task=push"],
        "env.task.observation=dict: the env observes a Dict (achieved_goal, desired_goal, observation)",
    ),
    (
        "unknown image pooling",
        ["cameras=wrist_depth", "model=cnn", "model.pooling=max"],
        "model.pooling='max': must be one of flat, keypoints",
    ),
    (
        "a stride too few",
        ["cameras=wrist_depth", "model=cnn", "model.strides=[4,2]"],
        "model.strides=[4, 2]: needs one entry per layer of model.channels=[16, 32, 32]",
    ),
    (
        "a camera inside the robot",
        ["cameras=fixed_depth", "model=cnn", "+env.camera.eye=[0,0,0.3]"],
        "camera.eye=[0.0, 0.0, 0.3] (the world frame): inside the robot's link panda_link1",
    ),
    (
        "a DAgger teacher on a camera that reports object cells",
        [*DEPTH_STUDENT, "+env.camera.object_cells=8"],
        "this env's privileged state has 109 (env.camera.object_cells adds the object's image cells)",
    ),
    (
        "object cells that do not divide the image",
        ["cameras=wrist_depth", "model=cnn", "+env.camera.object_cells=5"],
        "camera.object_cells=5: must be 0 (off) or a whole number of cells dividing the image's width 64 "
        "and height 64",
    ),
    (
        "inverted randomization range",
        ["env.randomization={object_mass:[1.0,0.5]}"],
        "'object_mass': low (1.0) is greater than high (0.5)",
    ),
    (
        "negative randomization range",
        ["randomization={object_mass:[-1.0,0.5]}"],
        "'object_mass': range [-1.0, 0.5] is outside the allowed",
    ),
    (
        "own objects: nothing matches",
        ["objects={paths:[{root}/nowhere/*.obj]}"],
        "nowhere/*.obj' matches no .urdf or .obj file",
    ),
    ("own objects: not a mesh", ["env.objects={paths:[{notamesh}]}"], "has no usable vertices"),
    (
        "unknown robot option",
        ["robot=ur5"],
        "robot=ur5: no such option; robot is one of kuka_iiwa, panda, xarm6",
    ),
    (
        "own arm: a joint not in the model",
        [f"robot={{{BAD_ARM}}}"],
        "env: robot.arm_joints: 'panda_joint9' is not a movable joint of ",
    ),
    (
        "own arm: a required key missing",
        ["robot={model:{root}/nowhere/arm.urdf}"],
        "env: robot.arm_joints: missing; a robot needs model, arm_joints",
    ),
    (
        "ADR parameter without a nominal value",
        ["randomization=adr", "~env.randomization.adr.params.object_mass.nominal"],
        "randomization adr parameter 'object_mass': needs ['nominal']",
    ),
    (
        "ADR parameter without limits",
        ["randomization=adr", "~env.randomization.adr.params.finger_force.limits"],
        "randomization adr parameter 'finger_force': needs ['limits']",
    ),
    (
        "ADR limits that exclude the nominal value",
        ["randomization=adr", "env.randomization.adr.params.object_mass.limits=[0.2,1.0]"],
        "'object_mass': limits [0.2, 1.0] exclude the nominal value 0.1",
    ),
    (
        "ADR step 0",
        ["randomization=adr", "env.randomization.adr.params.gravity_z.step=0"],
        "randomization adr parameter 'gravity_z': step must be > 0, got 0.0",
    ),
    (
        "ADR threshold above 1",
        ["randomization=adr", "env.randomization.adr.high_threshold=1.5"],
        "randomization adr.high_threshold=1.5: must be in [0, 1]",
    ),
    (
        "ADR low threshold not below the high one",
        ["randomization=adr", "env.randomization.adr.low_threshold=0.9"],
        "randomization adr.low_threshold=0.9: must be below high_threshold (0.7)",
    ),
    (
        "ADR buffer of 0",
        ["randomization=adr", "env.randomization.adr.buffer_size=0"],
        "randomization adr.buffer_size=0: must be an integer >= 1",
    ),
    ("CUDA on a machine without it", ["device=cuda"], "device='cuda': CUDA is not available"),
    ("no eval episodes", ["eval.episodes=0"], "eval.episodes=0: must be >= 1"),
    (
        "unknown evaluation randomization",
        ["eval.randomization=defualt"],
        "eval.randomization='defualt': unknown randomization preset 'defualt'; valid presets: none, default",
    ),
    ("keep no checkpoints", ["checkpoint.keep_last=0"], "checkpoint.keep_last=0: must be >= 1"),
    ("resume a missing path", ["resume={root}/nowhere"], "nowhere: no such file or directory"),
    ("resume a directory without checkpoints", ["resume={empty}"], "no checkpoints:"),
    ("resume a truncated checkpoint", ["resume={truncated}"], "unreadable checkpoint:"),
    ("resume a file that is not a checkpoint", ["resume={foreign}"], "unreadable checkpoint:"),
    ("resume a dict that is no checkpoint", ["resume={not_ckpt}"], "(missing actor, config, spec)"),
    ("resume NaN weights", ["resume={nan_weights}"], "holds 1 NaN or infinite value(s)"),
    ("resume a config that is a list", ["resume={config_list}"], "its config is a list, not a mapping"),
    (
        "resume with another model",
        ["resume={run}", "model.hidden_sizes=[32]"],
        "cannot change on resume: model.hidden_sizes: the checkpoint has [64, 64], the command line [32]",
    ),
    (
        "resume with another algorithm setting",
        ["resume={run}", "algo.loss.gamma=0.5"],
        "cannot change on resume: algo.loss.gamma",
    ),
    ("a fresh run into a run dir with checkpoints", ["hydra.run.dir={run}"], "already holds checkpoints"),
    ("an unwritable output directory", ["hydra.run.dir={unwritable}"], "cannot create the run directory"),
    ("demonstrations: a missing file", ["algo.demos={root}/no_demos"], "no_demos: no such file or directory"),
    (
        "demonstrations of another control mode",
        ["algo.demos={foreign_demos}"],
        "recorded with control_mode='joint_delta', this run has 'ee_delta'",
    ),
    (
        "demonstrations of no episode",
        ["algo.demos={empty_demos}"],
        "holds no demonstrations (0 episodes kept)",
    ),
    (
        "a demonstration decay above 1",
        ["algo.terms.imitation.decay=1.5"],
        "algo.terms.imitation.decay=1.5: must be in (0, 1]",
    ),
    (
        "a demonstration decay of 0",
        ["algo.terms.imitation.decay=0"],
        "algo.terms.imitation.decay=0.0: must be in (0, 1]",
    ),
    (
        "a negative demonstration weight",
        ["algo.terms.imitation.coeff=-1"],
        "algo.terms.imitation.coeff=-1.0: must be >= 0",
    ),
    (
        "a negative curiosity coefficient",
        ["algo.terms.rnd.coeff=-0.5"],
        "algo.terms.rnd.coeff=-0.5: must be >= 0",
    ),
    (
        "pre-training without demonstrations",
        ["algo.pretrain.epochs=5"],
        "algo.pretrain.epochs=5: needs algo.demos=",
    ),
    ("a negative seed", ["seed=-1"], "seed=-1: must be an integer in [0, 2**32)"),
    (
        "an experiment name that leaves the outputs folder",
        ["experiment_name=../escaped"],
        "experiment_name='../escaped': must be one folder name",
    ),
    (
        "an absolute experiment name",
        ["experiment_name=/tmp/escaped"],
        "experiment_name='/tmp/escaped': must be one folder name",
    ),
    (
        "an unknown critic loss",
        ["algo.loss.loss_critic_type=l3"],
        "algo.loss.loss_critic_type='l3': must be l1, l2 or smooth_l1",
    ),
    ("a clip range of 2", ["algo.loss.clip_epsilon=2"], "algo.loss.clip_epsilon=2.0: must be in (0, 1)"),
    ("an infinite learning rate", ["algo.optim.lr=inf"], "algo.optim.lr=inf: must be finite"),
    ("a KL target of 0", ["algo.schedule.target_kl=0"], "algo.schedule.target_kl=0.0: must be > 0 or null"),
    (
        "a negative final learning-rate fraction",
        ["algo.schedule.min_lr_frac=-1"],
        "algo.schedule.min_lr_frac=-1.0: must be in [0, 1]",
    ),
    ("no observation clip", ["model.obs_clip=0"], "model.obs_clip=0.0: must be > 0"),
    (
        "resume a policy file",
        [f"resume={ROOT}/policies/grasp_ppo.pt"],
        "is a policy file (no training state to continue)",
    ),
    ("an unknown algorithm", ["algo=dqn"], "algo=dqn: no such option; algo is one of distill, ppo, sac"),
    ("a seed above numpy's", ["seed=4294967296"], "seed=4294967296: must be an integer in [0, 2**32)"),
    (
        "resume a checkpoint of a newer format",
        ["resume={newer}"],
        NEWER_FORMAT_LINE,
    ),
    (
        "fine-tuning from a checkpoint of a newer format",
        ["algo.init_from={newer}"],
        NEWER_FORMAT_LINE,
    ),
    (
        "demonstrations without their frames",
        ["algo.demos={frameless_demos}"],
        "frames is missing (its demos.json came without the transitions",
    ),
    (
        "a tracking server that does not answer",
        ["logger=mlflow", "logger.tracking_uri=http://127.0.0.1:{closed_port}"],
        "no tracking server answers (Connection refused; waited up to 5 s)",
    ),
    (
        "own objects: a mesh of zero volume",
        ["env.objects={paths:[{flat}]}"],
        "flat.obj has zero volume (its vertices lie on one plane or line)",
    ),
]
EVAL = [
    ("a dict that is no checkpoint", ["ckpt={not_ckpt}"], "(missing actor, config, spec)"),
    ("NaN weights", ["ckpt={nan_weights}"], "holds 1 NaN or infinite value(s)"),
    ("an env that is a string", ["ckpt={env_string}"], "refused: config.env is a str, not a mapping"),
    ("a config that is a list", ["ckpt={config_list}"], "its config is a list, not a mapping"),
    ("spec.obs_dim a string", ["ckpt={obs_dim_str}"], "refused: spec.obs_dim='49' is not a whole number"),
    (
        "unknown objects option (a typo of random_urdfs_test)",
        ["objects=random_urdfs_tset"],
        "objects=random_urdfs_tset: no such option; objects is one of cube, primitives",
    ),
    (
        "unknown randomization option",
        ["randomization=widee"],
        "randomization=widee: no such option; randomization is one of adr, adr_objects, default, none, wide",
    ),
    (
        "own objects: nothing matches",
        ["objects={paths:[{root}/nowhere/*.obj]}"],
        "nowhere/*.obj' matches no .urdf or .obj file",
    ),
    ("own objects: not a mesh", ["objects={paths:[{notamesh}]}"], "notamesh.obj has no usable vertices"),
    (
        "own objects: not a mesh file (training's spelling)",
        ["env.objects={paths:[{notes}]}"],
        "notes.txt' matches no .urdf or .obj file",
    ),
    ("unknown key", ["episdoes=5"], "episdoes=5: unknown key 'episdoes'; the config has policy, ckpt"),
    ("wrong type", ["episodes=abc"], "episodes=abc: Value 'abc' of type 'str' could not be converted"),
    ("no episodes", ["episodes=0"], "episodes=0: must be at least 1"),
    ("no workers", ["workers=0"], "workers=0: must be at least 1"),
    ("missing checkpoint", ["ckpt={root}/nowhere.pt"], "missing checkpoint: "),
    ("truncated checkpoint", ["ckpt={truncated}"], "corrupt checkpoint: "),
    ("unknown env keyword", ["env.grip=1"], "env.grip: unknown key 'grip'; env has _target_, task, robot"),
    ("env the checkpoint cannot act in", ["env.control.mode=joint_delta"], "action layout mismatch"),
    (
        "a checkpoint of another arm",
        ["robot=kuka_iiwa"],
        "was trained on the robot 'panda' and the env has the robot 'kuka_iiwa': a policy does not",
    ),
    (
        "unknown video format",
        ["video=true", "video_format=avi"],
        "video_format=avi: must be auto, gif or mp4",
    ),
    ("an unwritable output directory", ["out_dir={unwritable}"], "cannot write the evaluation to"),
    (
        "unknown visual option (a typo of heldout)",
        ["visual=heldoutt"],
        "visual=heldoutt: no such option; visual is one of default, heldout, none, repaint, repaint_scales, "
        "wide",
    ),
    (
        "unknown cameras option",
        ["cameras=wrist"],
        "cameras=wrist: no such option; cameras is one of fixed_depth",
    ),
    (
        "a camera policy in an env without a camera",
        ["ckpt={student}", "cameras=none"],
        "is a camera policy (depth [1, 64, 64] + 29 state values) and the env has no camera "
        "(env.camera=null)",
    ),
    (
        "a state policy in an env with a camera",
        ["cameras=wrist_depth"],
        "is a state policy (45 state values) and the env has a camera (env.camera={mount: wrist, ",
    ),
    (
        "a camera policy given other images",
        ["ckpt={student}", "cameras=wrist_rgb"],
        "image mismatch: checkpoint reads depth [1, 64, 64], env gives rgb [3, 64, 64]",
    ),
    ("unknown camera key", ["ckpt={student}", "env.camera.fvo=60"], "camera: unknown key 'fvo'; valid keys"),
    (
        "a teacher for a state policy",
        ["teacher={teacher}"],
        "only a camera policy is compared with a teacher, this is a state policy",
    ),
    ("a missing teacher", ["ckpt={student}", "teacher={root}/nowhere.pt"], "nowhere.pt: missing checkpoint"),
    ("the checkpoint's teacher is gone", ["ckpt={orphan}"], "teacher=auto: the checkpoint's teacher"),
    (
        "a teacher of another control mode",
        ["ckpt={student}", "teacher={run}"],
        "env.control.mode='ee_delta' in the teacher, 'joint_delta' here",
    ),
    (
        "a camera policy as the teacher",
        ["ckpt={student}", "teacher={student}"],
        "the teacher must be a state policy",
    ),
    (
        "a checkpoint of a newer format",
        ["ckpt={newer}"],
        NEWER_FORMAT_LINE,
    ),
    ("a name with a path", ["name=../x"], "name='../x': must be one folder name (no '/', '..' or absolute"),
    ("an absolute name", ["name=/tmp/x"], "name='/tmp/x': must be one folder name"),
    ("own objects: a mesh of zero volume", ["objects={paths:[{flat}]}"], "flat.obj has zero volume"),
]
EXPORT = [
    (
        "unknown format",
        ["format=tflite"],
        "format=tflite: must be one of torchscript, onnx, pt2, all or folder",
    ),
    ("an unwritable output path", ["out={unwritable}/policy.pt"], "cannot write "),
    (
        "a file name for another format",
        ["format=pt2", "out={root}/policy.onnx"],
        "a pt2 file must end in .pt2",
    ),
    ("nothing to verify on", ["verify_obs=0"], "verify_obs=0: must be at least 1 (or verify=false)"),
    ("negative tolerance", ["tolerance=-1"], "tolerance=-1.0: must be >= 0"),
    ("missing checkpoint", ["ckpt={root}/nowhere.pt"], "missing checkpoint: "),
    ("a file that is not a checkpoint", ["ckpt={foreign}"], "corrupt checkpoint: "),
    ("unknown checkpoint kind", ["ckpt_kind=worst"], "ckpt_kind=worst: must be one of best, last"),
    ("unknown key", ["formatt=onnx"], "formatt=onnx: unknown key 'formatt'; the config has ckpt"),
    (
        "a camera checkpoint whose env gives other images",
        ["ckpt={mismatched}"],
        "image mismatch: checkpoint reads rgb [3, 64, 64], env gives depth [1, 64, 64]",
    ),
    (
        "a checkpoint of a newer format",
        ["ckpt={newer}"],
        NEWER_FORMAT_LINE,
    ),
]
ENJOY = [
    ("no episodes", ["episodes=0"], "episodes=0: must be at least 1"),
    ("negative speed", ["speed=-1"], "speed=-1.0: must be at least 0"),
    ("unknown render mode", ["render=vr"], "render=vr: must be human or none"),
    (
        "unknown objects option",
        ["objects=random_urdfs_tset"],
        "objects=random_urdfs_tset: no such option; objects is one of cube",
    ),
    (
        "own objects: nothing matches",
        ["objects={paths:[{root}/nowhere/*.obj]}"],
        "matches no .urdf or .obj file",
    ),
    ("missing checkpoint", ["ckpt={root}/nowhere.pt"], "missing checkpoint: "),
    ("unknown key", ["episdoes=5"], "episdoes=5: unknown key 'episdoes'"),
    ("unknown visual option", ["visual=heldoutt"], "visual=heldoutt: no such option; visual is one of"),
    (
        "a camera policy in an env without a camera",
        ["ckpt={student}", "cameras=none"],
        "is a camera policy (depth [1, 64, 64] + 29 state values) and the env has no camera",
    ),
    (
        "a checkpoint of another arm",
        ["robot=xarm6"],
        "was trained on the robot 'panda' and the env has the robot 'xarm6'",
    ),
    (
        "a checkpoint of a newer format",
        ["ckpt={newer}"],
        NEWER_FORMAT_LINE,
    ),
]
SWEEP = [
    (
        "unknown sweep",
        ["sweep=bogus"],
        "sweep=bogus: no such option; sweep is one of grasp_ppo, grasp_ppo_refine, grasp_ppo_speed, smoke",
    ),
    ("unknown sweep key", ["sweep.n_trial=3"], "sweep.n_trial=3: unknown key 'n_trial'; sweep has"),
    ("no trials", ["sweep.n_trials=0"], "sweep.n_trials=0: must be >= 1"),
    (
        "a metric training does not report",
        ["sweep.metric=accuracy"],
        "sweep.metric=accuracy: must be one of success_rate, mean_reward",
    ),
    ("unknown direction", ["sweep.direction=up"], "sweep.direction=up: must be one of maximize, minimize"),
    ("unknown sampler", ["sweep.sampler.name=grid"], "sweep.sampler.name=grid: must be one of tpe"),
    ("unknown training key", ["algo.lrr=1"], "algo.lrr=1: unknown key 'lrr'; algo has"),
    (
        "bad training value",
        ["algo.optim.lr=-1"],
        "a trial's training config: algo.optim.lr=-1.0: must be finite and > 0",
    ),
    (
        "a parameter naming no training key",
        ["+sweep.params.algo.lrr={type:float,low:0.1,high:0.2}"],
        "sweep.params: algo.lrr=0.1: unknown key 'lrr'",
    ),
    (
        "unknown distribution",
        ["sweep.params.algo.optim.lr={type:gauss}"],
        "sweep.params.algo.optim.lr: type must be float, int or categorical",
    ),
    (
        "own objects: nothing matches",
        ["objects={paths:[{root}/nowhere/*.obj]}"],
        "a trial's env: object path",
    ),
    ("an unwritable study directory", ["sweep.root_dir={unwritable}"], "cannot create"),
    ("a summary of no study", ["--summary"], "no study to summarize: "),
    (
        "a study name with a path",
        ["sweep.study_name=../x"],
        "sweep.study_name='../x': must be one folder name (no '/', '..' or absolute path)",
    ),
    ("an absolute study name", ["sweep.study_name=/tmp/x"], "sweep.study_name='/tmp/x': must be one folder"),
    (
        "a storage inside a file",
        ["sweep.storage={unwritable}/journal.log"],
        "a_file/out/journal.log: cannot open ",
    ),
    (
        "a database in a missing folder",
        ["sweep.storage=sqlite:///{root}/nowhere/study.db"],
        "nowhere/study.db: cannot open ",
    ),
]
DEMO = [
    ("no episodes", ["--episodes", "0"], "--episodes 0: must be at least 1"),
    ("wrong type", ["--episodes", "abc"], "argument --episodes: invalid int value: 'abc'"),
    (
        "unknown randomization preset",
        ["--randomization", "widee"],
        "--randomization widee: unknown randomization preset 'widee'; valid presets: none, default, wide",
    ),
    (
        "unknown object set",
        ["--objects", "random_urdfs_tset"],
        "--objects random_urdfs_tset: unknown object set 'random_urdfs_tset'; valid sets: cube",
    ),
    ("an unwritable output directory", ["--out", "{unwritable}"], "cannot write there"),
    ("negative seed", ["--seed", "-1"], "--seed -1: must be at least 0"),
    ("unknown task", ["--task", "pick"], "--task pick: unknown task; tasks: lift, pick_place, push, stack"),
    ("unknown arm", ["--robot", "ur5"], "--robot ur5: unknown arm; arms: panda, kuka_iiwa, xarm6"),
    ("a frame size that is not WxH", ["--size", "big"], "--size big: must be WIDTHxHEIGHT, each at least 16"),
    ("unknown flag", ["--bogus"], "unrecognized arguments: --bogus"),
]
DEMOS = [
    ("no episodes", ["episodes=0"], "episodes=0: must be at least 1"),
    ("keep neither", ["keep=some"], "keep=some: must be success or all"),
    (
        "the expert in another control mode",
        ["env.control.mode=joint_delta"],
        "env.control.mode=joint_delta: the scripted expert acts in ee_delta",
    ),
    ("a missing policy checkpoint", ["policy={root}/nowhere.pt"], "nowhere.pt: missing checkpoint"),
    ("unknown objects option", ["objects=random_urdfs_tset"], "objects=random_urdfs_tset: no such option"),
    ("an unwritable output directory", ["out={unwritable}"], "cannot write there"),
    (
        "a policy checkpoint of a newer format",
        ["policy={newer}"],
        NEWER_FORMAT_LINE,
    ),
]
TRAIN_SAC = [
    (
        "no gradient steps",
        ["algo.optim.utd_ratio=0"],
        "algo.optim.utd_ratio=0.0: must be > 0 (gradient steps per env frame)",
    ),
    (
        "a buffer smaller than a minibatch",
        ["algo.replay.buffer_frames=100"],
        "algo.replay.buffer_frames=100: must be >= algo.optim.batch_size (256): the buffer must hold a "
        "minibatch",
    ),
    (
        "demonstrations as the whole minibatch",
        ["algo.replay.demo_ratio=1"],
        "algo.replay.demo_ratio=1.0: must be in (0, 1)",
    ),
    ("a negative image shift", ["algo.augment.shift=-1"], "algo.augment.shift=-1: must be >= 0 (pixels)"),
    (
        "camera demonstrations recorded without a camera",
        ["cameras=wrist_depth", "model=cnn", "algo.demos={empty_demos}"],
        "recorded with the images {}, this run's camera gives {'depth': [1, 64, 64]}",
    ),
    (
        "camera demonstrations from another camera view",
        ["cameras=wrist_depth", "model=cnn", "algo.demos={behind_demos}"],
        "recorded with the camera view {'mount': 'wrist'",
    ),
    (
        "an auxiliary head on object cells the camera does not report",
        ["cameras=wrist_depth", "model=cnn", "algo.terms.aux.coeff=1", "algo.terms.aux.parts=[object_cells]"],
        "algo.terms.aux.parts: unknown part 'object_cells'; parts of the privileged state: arm_q, ",
    ),
    (
        "other grounds without the camera's ground mask",
        ["cameras=wrist_rgb", "model=cnn", "algo.augment.ground_swap=0.5"],
        "algo.augment.ground_swap=0.5: needs the camera's ground mask: an RGB camera and "
        "+env.camera.ground_mask=true",
    ),
    (
        "a ground mask on a depth camera",
        ["cameras=wrist_depth", "model=cnn", "+env.camera.ground_mask=true"],
        "camera.ground_mask=True: must be true or false, and true only with RGB (modality rgb or rgbd; "
        "here depth): a depth camera draws no ground body",
    ),
    (
        "an image replay buffer larger than the memory",
        ["cameras=wrist_depth", "model=cnn", "algo.replay.buffer_frames=1000000000"],
        "algo.replay.buffer_frames=1,000,000,000: the image replay buffer would take 15",
    ),
    (
        "no time for a batch",
        ["collector.worker_timeout_s=0"],
        "collector.worker_timeout_s=0.0: must be > 0 (seconds a batch may take)",
    ),
]
REPORT = [
    ("no bootstrap resamples", ["--reps", "0"], "--reps 0: must be at least 1 (bootstrap resamples)"),
]
CASES = [
    (entry, *case)
    for entry, cases in (
        ("train", TRAIN),
        ("train_sac", TRAIN_SAC),
        ("eval", EVAL),
        ("export", EXPORT),
        ("enjoy", ENJOY),
        ("sweep", SWEEP),
        ("demo", DEMO),
        ("demos", DEMOS),
        ("report", REPORT),
    )
    for case in cases
]


def _fill(args: list[str], root: Path, paths: dict[str, str]) -> list[str]:
    out = []
    for a in args:
        for name, value in {"root": str(root), **paths}.items():
            a = a.replace("{" + name + "}", value)
        out.append(a)
    return out


def error_lines(out: str, err: str) -> list[str]:
    """The error lines printed: ``error: ...``, and any logged ``[ERROR]`` line (a second line fails)."""
    return [ln for ln in our_lines(out + "\n" + err) if ln.startswith("error:") or "[ERROR]" in ln]


def _snapshot(root: Path) -> list[Path]:
    return sorted(root.rglob("*"))


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    root = tmp_path_factory.mktemp("bad_input")
    return root, _files(root)


@pytest.mark.parametrize(("entry", "what", "args", "message"), CASES, ids=[f"{c[0]}: {c[1]}" for c in CASES])
def test_bad_input_gives_one_line_and_leaves_nothing(files, capsys, entry, what, args, message) -> None:
    root, paths = files
    before = _snapshot(root)
    code = run_entry(entry, _fill([*BASE[entry], *args], root, paths), root)
    out = capsys.readouterr()
    shown = out.out + out.err
    assert code != 0, shown
    assert "Traceback" not in shown, shown
    errors = error_lines(out.out, out.err)
    assert len(errors) == 1 and message in errors[0], shown
    assert our_lines(out.err) == errors, shown
    after = _snapshot(root)
    assert after == before, f"left behind: {set(after) - set(before)}"


def test_far_more_workers_than_cores_is_a_warning_not_an_error(caplog, monkeypatch) -> None:
    """64 workers on 2 cores run, slowly: one warning naming both counts, and validation passes."""
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    cfg = compose_train([*SMOKE, "collector.num_workers=64"])

    def warnings() -> list[str]:
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="rlgrasp.train"):
            validate_train(cfg)
        return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]

    assert warnings() == [
        "collector.num_workers=64 on a machine with 2 cores: each worker gets a fraction "
        "of a core (collector.num_workers=2 or fewer is usually fastest)"
    ]
    cfg.collector.num_workers = 4
    assert warnings() == []  # up to twice the cores: no line


def _as_documented(text: str, tmp: str, paths: dict[str, str]) -> str:
    """``text`` without what differs from one machine or run of the table to the next: the
    temporary folder, the closed port, the checkout's and the installed packages' folders."""
    port = f"127.0.0.1:{paths['closed_port']}"
    site = str(Path(pybullet_data.getDataPath()).parent)
    return (
        text.replace(tmp, "...")
        .replace(port, "127.0.0.1:<closed port>")
        .replace(f"{ROOT}/", "")
        .replace(site, ".../site-packages")
    )


def _table() -> str:
    """The bad-input table of the docs: each case and the line it prints, per entry point."""
    sections = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        paths = _files(root)
        for entry, script in COMMANDS.items():
            rows = []
            for _, what, args, _ in (c for c in CASES if c[0] == entry):
                out, err = io.StringIO(), io.StringIO()
                with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                    code = run_entry(entry, _fill([*BASE[entry], *args], root, paths), root)
                lines = error_lines(out.getvalue(), err.getvalue()) or ["(no error line)"]
                line = _as_documented(lines[0], tmp, paths).replace("|", "\\|")
                shown = _as_documented(" ".join(_fill(args, root, paths)), tmp, paths)
                rows.append((what, f"`{shown}`", code, line))
            sections.append(
                f"### `{script}`\n\n" + markdown_table(["input", "arguments", "exit", "message"], rows)
            )
    return "\n\n".join(sections)


if __name__ == "__main__":
    print(_table())
