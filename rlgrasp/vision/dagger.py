"""DAgger's pieces: the teacher reading privileged state, the policy the workers run (teacher or
student acts, the teacher always labels), and the aggregated dataset of labelled frames."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers import RandomSampler
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.envs.env_settings import ACTION_SETTINGS, env_setting
from rlgrasp.envs.robot import robot_label
from rlgrasp.models.mlp import OBS_KEY
from rlgrasp.models.spec import PRIVILEGED_KEY
from rlgrasp.policy_file import CheckpointError, load_checkpoint, policy_from_checkpoint

LABEL_KEY = "teacher_action"


class PrivilegedTeacher(TensorDictModuleBase):
    """A state policy (a checkpoint of a state run) acting on the env's ``privileged`` entry, which
    is exactly the flat observation it was trained on."""

    def __init__(self, policy: TensorDictModuleBase):
        super().__init__()
        self.policy = policy
        self.in_keys, self.out_keys = [PRIVILEGED_KEY], ["action"]

    @torch.no_grad()
    def forward(self, td: TensorDictBase) -> TensorDictBase:
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            out = self.policy(TensorDict({OBS_KEY: td[PRIVILEGED_KEY]}, td.batch_size))
        td["action"] = out["action"]
        return td


def load_teacher(path: str, spec: dict[str, Any], env_cfg: Any) -> tuple[PrivilegedTeacher, dict[str, Any]]:
    """The teacher of ``path``, refused in one line when it cannot read this env's privileged state
    or drive this env's action."""
    ckpt = load_checkpoint(path)
    t_spec, t_env = ckpt["spec"], ckpt["config"]["env"]
    # The arm first: the Panda and the iiwa share the state's size while every joint means another thing.
    trained, here = robot_label(t_env.get("robot", "panda")), robot_label(env_cfg.get("robot", "panda"))
    if trained != here:
        raise CheckpointError(
            f"teacher={path}: it was trained on the robot {trained!r} and this env has the robot {here!r}: "
            f"a teacher does not transfer between arms (give a teacher of {here!r})"
        )
    if t_spec["obs_dim"] != spec["privileged_dim"]:
        cells = "object_cells" in spec.get("privileged_parts", {})  # a state teacher never read them
        why = (
            "env.camera.object_cells adds the object's image cells"
            if cells
            else "another robot, control mode or observation layout"
        )
        raise CheckpointError(
            f"teacher={path}: it reads {t_spec['obs_dim']} state values, this env's privileged state has "
            f"{spec['privileged_dim']} ({why})"
        )
    for key in ACTION_SETTINGS:
        theirs, ours = env_setting(t_env, key), env_setting(env_cfg, key)
        if theirs != ours:
            raise CheckpointError(f"teacher={path}: env.{key}={theirs!r} in the teacher, {ours!r} here")
    return PrivilegedTeacher(policy_from_checkpoint(ckpt)), ckpt


class DAggerPolicy(TensorDictModuleBase):
    """What the workers run: with probability ``beta`` (per env and step) the teacher acts, else the
    student; the teacher's action is recorded either way as the label. ``beta`` is a buffer, so it
    reaches the workers with the weights."""

    def __init__(self, student: TensorDictModuleBase, teacher: PrivilegedTeacher, beta: float = 1.0):
        super().__init__()
        self.student, self.teacher = student, teacher
        self.register_buffer("beta", torch.tensor(float(beta)))
        self.in_keys = list(dict.fromkeys([*student.in_keys, PRIVILEGED_KEY]))
        self.out_keys = ["action", LABEL_KEY]

    @torch.no_grad()
    def forward(self, td: TensorDictBase) -> TensorDictBase:
        label = self.teacher(td.select(PRIVILEGED_KEY))["action"]
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            student = self.student(td.select(*self.student.in_keys))["action"]
        use_teacher = torch.rand(td.batch_size, device=label.device) < self.beta
        td["action"] = torch.where(use_teacher.unsqueeze(-1), label, student)
        td[LABEL_KEY] = label
        return td


class LabelledFrames:
    """Every frame collected so far with its teacher label (DAgger aggregates), up to ``capacity``
    (then the oldest go first), sampled uniformly for the student's updates."""

    def __init__(self, keys: Sequence[str], capacity: int, minibatch: int):
        self.keys = [*keys, LABEL_KEY]
        self.buffer = ReplayBuffer(
            storage=LazyTensorStorage(capacity), sampler=RandomSampler(), batch_size=minibatch
        )

    def extend(self, batch: TensorDictBase) -> None:
        self.buffer.extend(batch.reshape(-1).select(*self.keys).clone())

    def __len__(self) -> int:
        return len(self.buffer)

    def sample(self) -> TensorDictBase:
        return self.buffer.sample()
