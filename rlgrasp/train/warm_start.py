"""Start a PPO run from a trained policy: PPO fine-tuning of a distilled camera student.

A student distilled by DAgger copies its teacher and never sees a reward, so what imitation cannot
teach (the teacher's own failures, the states where a small error tips the object) stays in it.
``algo.init_from`` starts a fresh PPO run's actor from such a checkpoint; the critic starts fresh
(a shipped policy holds no critic), so ``algo.schedule.critic_warmup_frames`` lets it learn the student's
returns before its advantages move the actor. The exploration std is this run's
``model.init_log_std``, not the checkpoint's: a student is trained deterministically and its std
never moved from its initial value.
"""

from __future__ import annotations

from typing import Any

from torch import nn

from rlgrasp.envs.env_settings import ACTION_SETTINGS, env_setting
from rlgrasp.envs.robot import robot_label
from rlgrasp.policy_file import CheckpointError, load_checkpoint, resolve_policy_path
from rlgrasp.utils import plain

STD_KEY = "scale.state_independent_scale"  # the actor's state-independent std (TorchRL's module)


def warm_start(actor: nn.Module, path: str, env_cfg: Any, model_cfg: Any) -> str:
    """Load the policy of ``path`` (a checkpoint or run directory; relative paths also from the
    repository root) into ``actor``, all but its std; returns a line for the log. Refused in one line
    when the policy was trained for another arm, control mode or camera, or with another model."""
    where = f"algo.init_from={path}"
    source = resolve_policy_path(path)  # a relative path: also from the repository root
    try:
        ckpt = load_checkpoint(source)
    except CheckpointError as exc:
        raise CheckpointError(f"{where}: {exc}") from exc
    trained_env, trained_model = ckpt["config"]["env"], ckpt["config"]["model"]
    trained, here = robot_label(trained_env.get("robot", "panda")), robot_label(env_cfg.get("robot", "panda"))
    if trained != here:
        raise CheckpointError(f"{where}: its policy drives the robot {trained!r}, this env has {here!r}")
    differences = _env_differences(trained_env, plain(env_cfg))
    if differences:
        key, theirs, ours = differences[0]
        raise CheckpointError(
            f"{where}: env.{key}={theirs!r} in the checkpoint, {ours!r} here (fine-tune in the env it was "
            "trained in)"
        )
    weights = {k: v for k, v in ckpt["actor"].items() if not k.endswith(STD_KEY)}
    try:
        missing, unexpected = actor.load_state_dict(weights, strict=False)
    except RuntimeError as exc:  # a shape differs
        missing, unexpected = [str(exc).splitlines()[-1].strip()[:160]], []
    missing = [k for k in missing if not k.endswith(STD_KEY)]
    if missing or unexpected:
        raise CheckpointError(
            f"{where}: its policy does not fit this run's model ({(missing or unexpected)[0]}); "
            f"it was trained with model={trained_model.get('name')} {_model_keys(trained_model)}"
        )
    return (
        f"actor from {where} ({ckpt.get('frames', 0):,} frames), std from "
        f"model.init_log_std={model_cfg.init_log_std}"
    )


def _env_differences(trained: dict[str, Any], here: dict[str, Any]) -> list[tuple[str, Any, Any]]:
    """What the policy's inputs and outputs depend on, where the two envs differ: the camera first
    (key by key, so that a checkpoint written before a camera key existed is compared on the keys it
    has), then the action."""
    theirs, ours = trained.get("camera") or {}, here.get("camera") or {}
    if bool(theirs) != bool(ours):
        out = [("camera", theirs or None, ours or None)]
    else:
        out = [(f"camera.{k}", v, ours.get(k)) for k, v in theirs.items() if ours.get(k) != v]
    return out + [
        (k, env_setting(trained, k), env_setting(here, k))
        for k in ACTION_SETTINGS
        if env_setting(trained, k) != env_setting(here, k)
    ]


def _model_keys(model: dict[str, Any]) -> str:
    shown = ("channels", "kernel_sizes", "strides", "pooling", "image_features", "hidden_sizes")
    return " ".join(f"model.{k}={model[k]}" for k in shown if k in model)
