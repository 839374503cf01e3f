"""A camera policy's teacher, evaluated beside it: which checkpoint, checked against the camera env.

The teacher is the state policy a camera student was distilled from (``rlgrasp.algos.dagger``). It
runs in the very env the student runs in, on the same seeds, reading the ``privileged`` entry (the
flat state it was trained on); the camera env's physics of a seed do not depend on the camera or the
visuals, so both face the same episodes and the student/teacher ratio measures what the camera costs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from rlgrasp.envs.env_settings import ACTION_SETTINGS, env_setting
from rlgrasp.evaluation.policies import PolicySource, build_policy
from rlgrasp.evaluation.source import (
    ENV_ERRORS,
    POLICY_KEYS,
    EvaluationError,
    describe_policy,
    load_checked_checkpoint,
    resolve_checkpoint_path,
)
from rlgrasp.models.cnn import image_specs
from rlgrasp.policy_file import resolve_policy_path

#: Env keys a teacher must share with the student's env beyond the layout (same sizes, other meaning).
SAME_ENV_KEYS = ACTION_SETTINGS


def teacher_path(value: str, source: PolicySource) -> Path | None:
    """The teacher checkpoint ``teacher=value`` names for ``source``, or ``None`` for no teacher."""
    if value == "none":
        return None
    is_student = source.ckpt is not None and bool(image_specs(source.ckpt["spec"]))
    if value == "auto":
        recorded = (source.info or {}).get("teacher") if is_student else None
        if not recorded:
            return None
        recorded = resolve_policy_path(str(recorded))
        if not Path(recorded).expanduser().exists():
            raise EvaluationError(
                f"teacher=auto: the checkpoint's teacher {recorded} does not exist here; "
                "give teacher=<checkpoint file or run dir>, or teacher=none"
            )
        value = str(recorded)
    elif not is_student:
        what = describe_policy(source.ckpt["spec"]) if source.ckpt else f"policy={source.kind}"
        raise EvaluationError(
            f"teacher={value}: only a camera policy is compared with a teacher, this is {what}; "
            "use teacher=none"
        )
    try:  # a run directory: its last.pt, the checkpoint distillation loads from one
        return resolve_checkpoint_path(resolve_policy_path(value), "last")
    except EvaluationError as exc:
        raise EvaluationError(f"teacher={value}: {exc}") from exc


def prepare_teacher(value: str, source: PolicySource) -> PolicySource | None:
    """The teacher's ``PolicySource`` (the student's env, ``privileged`` read), checked and dry-run
    like the student's; ``None`` when there is none to evaluate."""
    path = teacher_path(value, source)
    if path is None:
        return None
    where = f"teacher={value}"
    try:
        full = load_checked_checkpoint(path)
    except EvaluationError as exc:
        raise EvaluationError(f"{where}: {exc}") from exc
    spec, t_env = full["spec"], full["config"].get("env") or {}
    if image_specs(spec):
        raise EvaluationError(
            f"{where}: the teacher must be a state policy, {path} is {describe_policy(spec)}"
        )
    for key in SAME_ENV_KEYS:
        theirs, ours = env_setting(t_env, key), env_setting(source.env_cfg, key)
        if theirs != ours:
            raise EvaluationError(f"{where}: env.{key}={theirs!r} in the teacher, {ours!r} here")
    teacher = dataclasses.replace(
        source,
        ckpt={k: full[k] for k in POLICY_KEYS if k in full},
        ckpt_path=str(path.resolve()),
        run_dir=None,
        info={"path": str(path.resolve()), "frames": full.get("frames")},
        privileged=True,
    )
    _dry_run(teacher, where)
    return teacher


def _dry_run(teacher: PolicySource, where: str) -> None:
    """Its layout against the env's ``privileged`` entry and one action, before any episode."""
    try:
        env = teacher.make_env()
    except ENV_ERRORS as exc:
        raise EvaluationError(f"cannot build the env for {where}: {exc}") from exc
    try:
        spec, space = teacher.ckpt["spec"], env.observation_space
        privileged = int(space["privileged"].shape[-1])
        if int(spec["obs_dim"]) != privileged or int(spec["action_dim"]) != env.action_space.shape[0]:
            raise EvaluationError(
                f"{where}: it reads {spec['obs_dim']} state values and acts with {spec['action_dim']}, "
                f"this env's privileged state has {privileged} and its action {env.action_space.shape[0]}"
            )
        try:
            actor = build_policy(teacher, env, deterministic=True)
        except (RuntimeError, KeyError, TypeError, ValueError) as exc:
            raise EvaluationError(f"{where}: the policy cannot be rebuilt ({exc})") from exc
        obs, _ = env.reset(seed=0)
        actor.reset(0)
        np.asarray(actor(obs))
    finally:
        env.close()
