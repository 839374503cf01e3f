"""Where the policy and the env come from: a checkpoint alone, or a baseline with no checkpoint.

Everything is validated here, before anything is written: a missing or corrupt file, a file that
is not an rlgrasp checkpoint, or a checkpoint whose observation/action layout does not match the
env being built each raise ``EvaluationError`` with a message saying which.
"""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from hydra.errors import InstantiationException
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from rlgrasp.envs.env_settings import env_setting
from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.envs.robot import robot_label
from rlgrasp.evaluation.policies import POLICIES, PolicySource, build_policy
from rlgrasp.models.cnn import image_specs
from rlgrasp.overrides import explain
from rlgrasp.policy_file import CheckpointError, is_policy_folder, read_checkpoint
from rlgrasp.received import ReceivedError, check_inside

CKPT_KINDS = ("best", "last")
# What a checkpoint must hold for evaluation (see rlgrasp.train.checkpoint's docstring).
REQUIRED_KEYS = ("actor", "config", "spec")
#: What the policy is rebuilt from: the required entries and, for a camera policy, ``kind``.
POLICY_KEYS = (*REQUIRED_KEYS, "kind")
REQUIRED_SPEC = ("obs_dim", "action_dim", "action_low", "action_high")
#: What building an env from user input raises: a bad keyword (ValueError, TypeError), a missing or
#: unreadable object file (OSError), a ``_target_`` that does not import.
ENV_ERRORS = (ValueError, TypeError, OSError, ImportError, AttributeError, InstantiationException)


class EvaluationError(RuntimeError):
    """A user-facing problem with the evaluation's input (printed without a traceback)."""


def resolve_checkpoint_path(ckpt: str | os.PathLike, kind: str = "best") -> Path:
    """A checkpoint file or a policy folder (``model.safetensors`` + ``config.json``) as given, or
    ``<run dir>/checkpoints/<kind>.pt`` for a run directory."""
    if kind not in CKPT_KINDS:
        raise EvaluationError(f"ckpt_kind={kind}: must be one of {', '.join(CKPT_KINDS)}")
    path = Path(ckpt).expanduser()
    if path.is_dir() and not is_policy_folder(path):
        ckpt_dir = path / "checkpoints"
        candidate = ckpt_dir / f"{kind}.pt"
        if not candidate.is_file():
            found = sorted(p.name for p in ckpt_dir.glob("*.pt")) if ckpt_dir.is_dir() else []
            hint = f"; it has {', '.join(found)}" if found else "; it has no checkpoints"
            other = "last" if kind == "best" else "best"
            if f"{other}.pt" in found:
                hint += f" (use ckpt_kind={other})"
            raise EvaluationError(
                f"missing checkpoint: run directory {path} has no checkpoints/{kind}.pt{hint}"
            )
        return candidate
    if not path.exists():
        raise EvaluationError(f"missing checkpoint: {path} does not exist")
    return path


def run_of(path: Path) -> Path | None:
    """The run a checkpoint belongs to (``<run dir>/checkpoints/<file>.pt``), where the evaluation
    writes by default; refused when a link is on the way: a link would move that output (and the
    file read) to wherever it points, so the run is the folder as given, never a link's target."""
    if path.parent.name != "checkpoints":
        return None
    run_dir = path.absolute().parent.parent
    try:
        check_inside(run_dir, path, f"checkpoint {path}")
    except ReceivedError as exc:
        raise EvaluationError(str(exc)) from None
    return run_dir


def load_checked_checkpoint(path: Path) -> dict[str, Any]:
    """Load and check the checkpoint as every reader does (``rlgrasp.train.checkpoint.read_checkpoint``:
    its config read as data), and that it holds what evaluation needs; each problem in one line."""
    try:
        ckpt = read_checkpoint(path)
    except CheckpointError as exc:  # evaluation's own words for a file it cannot use at all
        message = str(exc).replace("unreadable checkpoint: ", "corrupt checkpoint: ", 1)
        if message.startswith("not an rlgrasp training checkpoint: "):
            why = message.split(" (", 1)[-1]
            message = f"corrupt checkpoint: {path} is not an rlgrasp training checkpoint ({why}"
        raise EvaluationError(message) from None
    missing = [k for k in REQUIRED_KEYS if k not in ckpt]
    missing += [f"spec.{k}" for k in REQUIRED_SPEC if k not in (ckpt.get("spec") or {})]
    if missing:
        raise EvaluationError(
            f"corrupt checkpoint: {path} is not an rlgrasp training checkpoint (missing {', '.join(missing)})"
        )
    return ckpt


#: The env's parts whose keywords an evaluation override changes one by one: ``env.control.ee_yaw=true``
#: keeps the checkpoint's control mode, ``env.task.air_fraction=0`` its task. The other parts (the
#: robot, the objects, the randomization) are a choice of one thing, replaced whole.
KEYWORD_PARTS = ("task", "control", "sim", "camera")


def _over(key: str, trained: Any, given: Any) -> Any:
    """What an evaluation override ``given`` makes of the checkpoint's ``env.<key>``: its keywords on
    top of the checkpoint's for a part of ``KEYWORD_PARTS`` of the same class, else ``given``."""
    same_part = (
        isinstance(trained, dict)
        and isinstance(given, dict)
        and given.get("_target_", trained.get("_target_")) == trained.get("_target_")
    )
    return {**trained, **given} if key in KEYWORD_PARTS and same_part else given


def build_env_cfg(
    env_cfg: dict[str, Any] | None, randomization: Any = None, overrides: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The env's ``_target_`` node: a training ``env`` config (``None``: the env's defaults), with
    evaluation's overrides on top and rendering on. Keys of the grasp env are type-checked."""
    # A checkpoint's env node was read as data (rlgrasp.received): its _target_ is rlgrasp's own,
    # and an env of before the task part has its reward keys under env.task.
    cfg = dict(env_cfg or asdict(EnvConfig()))
    for key, value in (overrides or {}).items():
        cfg[key] = _over(key, cfg.get(key), value)
    if randomization is not None:
        cfg["randomization"] = randomization
    cfg["render_mode"] = "rgb_array"
    if cfg.get("_target_") == EnvConfig._target_:
        try:
            cfg = OmegaConf.to_container(OmegaConf.merge(OmegaConf.structured(EnvConfig), cfg))
        except OmegaConfBaseException as exc:
            raise EvaluationError(f"env.{explain(exc, root='env')}") from exc
    return cfg


def describe_policy(spec: dict[str, Any]) -> str:
    """``a camera policy (depth [1, 64, 64] + 29 state values)`` or ``a state policy (42 values)``."""
    images = image_specs(spec)
    if images:
        seen = " + ".join(f"{k} {list(shape)}" for k, shape in images.items())
        return f"a camera policy ({seen} + {spec['obs_dim']} state values)"
    return f"a state policy ({spec['obs_dim']} state values)"


def describe_camera(env: Any) -> str:
    """The env's camera as its config names it: ``env.camera={mount: wrist, modality: depth, 64x64}``."""
    camera = getattr(env.unwrapped, "camera", None)
    if camera is None:
        return "no camera (env.camera=null)"
    s = camera.spec
    return f"a camera (env.camera={{mount: {s.mount}, modality: {s.modality}, {s.width}x{s.height}}})"


def check_layout(spec: dict[str, Any], env: Any, where: str) -> None:
    """The checkpoint's observation and action layout must match the env being built: a camera
    policy needs the same images and state size, a state policy an env without a camera."""
    space = env.observation_space
    camera_env = isinstance(space, gym.spaces.Dict)
    images = image_specs(spec)
    if bool(images) != camera_env:
        fix = "use cameras=none (env.camera=null)" if camera_env else "drop cameras=none / env.camera=null"
        raise EvaluationError(
            f"{where} is {describe_policy(spec)} and the env has {describe_camera(env)}: {fix}"
        )
    problems = []
    obs_shape = tuple(space["state"].shape if camera_env else space.shape)
    if obs_shape != (int(spec["obs_dim"]),):
        problems.append(
            f"observation layout mismatch: checkpoint obs_dim={spec['obs_dim']}, "
            f"env {'state' if camera_env else 'observation'} shape {obs_shape}"
        )
    env_images = {k: tuple(space[k].shape) for k in ("depth", "rgb") if camera_env and k in space.spaces}
    if env_images != images:
        problems.append(
            f"image mismatch: checkpoint reads {_images(images)}, env gives {_images(env_images)}"
        )
    problems += _action_problems(spec, env.action_space)
    if problems:
        raise EvaluationError(f"{where}: " + "; ".join(problems))


def _images(shapes: dict[str, tuple[int, ...]]) -> str:
    return ", ".join(f"{k} {list(v)}" for k, v in shapes.items()) or "none"


def _action_problems(spec: dict[str, Any], act_space: Any) -> list[str]:
    if tuple(act_space.shape) != (int(spec["action_dim"]),):
        return [
            f"action layout mismatch: checkpoint action_dim={spec['action_dim']}, "
            f"env action shape {tuple(act_space.shape)}"
        ]
    low, high = np.asarray(spec["action_low"], float), np.asarray(spec["action_high"], float)
    if not (np.allclose(low, act_space.low) and np.allclose(high, act_space.high)):
        return [
            f"action bounds mismatch: checkpoint [{low.tolist()}, {high.tolist()}], "
            f"env [{act_space.low.tolist()}, {act_space.high.tolist()}]"
        ]
    return []


def _checkpoint_info(full: dict[str, Any], path: Path, kind: str) -> dict[str, Any]:
    """What an evaluation reports of the checkpoint: where it is, how far it trained, on what."""
    env_cfg = full["config"].get("env") or {}
    return {
        "path": str(path.resolve()),
        "kind": kind,
        "frames": full.get("frames"),
        "updates": full.get("updates"),
        "best_eval_success": full.get("best_eval_success"),
        "last_eval": full.get("last_eval"),
        "run_dir": full.get("run_dir"),
        "versions": full.get("versions"),
        "experiment_name": full["config"].get("experiment_name"),
        "train_seed": full["config"].get("seed"),
        # What it was trained on: an evaluation elsewhere says so (rlgrasp.evaluation.cli.conditions).
        "train_objects": env_cfg.get("objects", "cube"),
        "train_randomization": env_cfg.get("randomization", "default"),
        "train_visual": env_setting(env_cfg, "sim.visual"),
        "train_camera": env_cfg.get("camera"),
        "teacher": _teacher_of(full["config"].get("algo") or {}),
    }


def _source_kind(path: Path, ckpt: str, ckpt_kind: str) -> str:
    """What an evaluation reports the checkpoint was: ``best``/``last`` of a run, a file, a folder."""
    if is_policy_folder(path):
        return "folder"
    return ckpt_kind if Path(ckpt).is_dir() else "file"


def prepare(
    policy: str,
    ckpt: str | None = None,
    ckpt_kind: str = "best",
    randomization: Any = None,
    env_overrides: dict[str, Any] | None = None,
) -> PolicySource:
    """Resolve, load and validate everything; build one env and one policy call as a dry run."""
    if policy not in POLICIES:
        raise EvaluationError(f"policy={policy}: must be one of {', '.join(POLICIES)}")
    if policy == "checkpoint":
        if not ckpt:
            raise EvaluationError(
                "ckpt=<run dir, checkpoint file or policy folder> is required "
                "(or policy=scripted / policy=random)"
            )
        path = resolve_checkpoint_path(ckpt, ckpt_kind)
        full = load_checked_checkpoint(path)
        env_cfg = full["config"].get("env") or {}
        if not env_cfg:
            raise EvaluationError(f"corrupt checkpoint: {path} has no config['env'] to rebuild the env from")
        trimmed = {k: full[k] for k in POLICY_KEYS if k in full}
        if randomization is None:  # what the run's own evaluations played, if it chose (eval.randomization)
            randomization = (full["config"].get("eval") or {}).get("randomization")
        info = _checkpoint_info(full, path, _source_kind(path, ckpt, ckpt_kind))
        run_dir = run_of(path)
    else:
        if ckpt:
            raise EvaluationError(
                f"policy={policy} takes no checkpoint; drop ckpt={ckpt} (or use policy=checkpoint)"
            )
        env_cfg, trimmed, path, run_dir = None, None, None, None
        info = {}
    source = PolicySource(
        kind=policy,
        env_cfg=build_env_cfg(env_cfg, randomization, env_overrides),
        ckpt=trimmed,
        ckpt_path=str(path.absolute()) if path else None,
        run_dir=str(run_dir) if run_dir else None,
        info=info,
    )
    if source.ckpt is not None:
        check_robot(env_cfg, source.env_cfg, f"checkpoint {source.ckpt_path}")
    _dry_run(source)
    return source


def check_robot(trained_env: dict[str, Any], env_cfg: dict[str, Any], where: str) -> None:
    """A policy never leaks across arms: another arm may share the observation's size (the Panda and
    the iiwa both have 7 joints) while every joint means something else."""
    trained, here = (robot_label(cfg.get("robot", "panda")) for cfg in (trained_env, env_cfg))
    if trained != here:
        raise EvaluationError(
            f"{where} was trained on the robot {trained!r} and the env has the robot {here!r}: a policy "
            f"does not transfer between arms (drop robot=/env.robot=, or evaluate a checkpoint of {here!r})"
        )


def _dry_run(source: PolicySource) -> None:
    """Build the env and the policy once and act on the first observation: fail here, not in a worker."""
    where = f"checkpoint {source.ckpt_path}" if source.ckpt_path else f"policy={source.kind}"
    try:
        env = source.make_env()
    except ENV_ERRORS as exc:  # the env's own message names the keyword and what it allows
        raise EvaluationError(f"cannot build the env for {where}: {exc}") from exc
    try:
        if source.ckpt is not None:
            check_layout(source.ckpt["spec"], env, where)
        try:
            act = build_policy(source, env, deterministic=True)
        except (RuntimeError, KeyError, TypeError, ValueError) as exc:
            raise EvaluationError(
                f"corrupt checkpoint: {where}: the policy cannot be rebuilt ({exc})"
            ) from exc
        try:
            obs, _ = env.reset(seed=0)
        except ENV_ERRORS as exc:
            raise EvaluationError(f"cannot reset the env for {where}: {exc}") from exc
        act.reset(0)
        action = np.asarray(act(obs))
        if action.shape != env.action_space.shape:
            raise EvaluationError(
                f"{where}: action layout mismatch: the policy returns shape {action.shape}, "
                f"the env expects {env.action_space.shape}"
            )
    finally:
        env.close()


def _teacher_of(algo: dict[str, Any]) -> str | None:
    """The state teacher a camera policy learned from: DAgger's ``algo.teacher``, or the checkpoint of
    PPO's teacher term (``algo.terms.teacher.checkpoint``)."""
    term = (algo.get("terms") or {}).get("teacher") or {}
    return algo.get("teacher") or term.get("checkpoint")
