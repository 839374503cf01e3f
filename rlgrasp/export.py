"""Export a trained policy for deployment: one file, raw inputs in, deterministic action out.

The file holds ``rlgrasp.deploy``'s module: a state policy reads one ``observation`` vector, a camera
policy also its images (``depth`` float32 metres, ``rgb`` uint8, channel first). Every export is
checked against the checkpoint policy on observations recorded from env rollouts (the camera env's,
for a camera policy), and a JSON file beside it names the inputs (names, shapes, dtypes) and says
what the vectors mean. ``format=folder`` writes a policy folder instead (``rlgrasp.policy_folder``):
data, not a program, read back by rlgrasp and checked to act exactly as the checkpoint.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import inspect
import io
import logging
import os
import shutil
import sys
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import hydra
import numpy as np
import torch
from hydra.core.config_store import ConfigStore
from torch import nn

from rlgrasp.config import CONFIG_DIR
from rlgrasp.deploy import DeployPolicy, deploy_module
from rlgrasp.envs.control import ControlConfig
from rlgrasp.envs.env_settings import env_setting
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.observation import PROPRIOCEPTION
from rlgrasp.evaluation.policies import CheckpointActor
from rlgrasp.evaluation.source import (
    CKPT_KINDS,
    ENV_ERRORS,
    EvaluationError,
    build_env_cfg,
    check_layout,
    load_checked_checkpoint,
    resolve_checkpoint_path,
)
from rlgrasp.models.cnn import image_specs
from rlgrasp.models.mlp import squashes
from rlgrasp.overrides import entry_point, unwritable
from rlgrasp.policy_file import (
    CONFIG,
    INSTALL,
    WEIGHTS,
    CheckpointError,
    is_policy_folder,
    package_versions,
    read_checkpoint,
)
from rlgrasp.policy_folder import write_policy_folder
from rlgrasp.received import ReceivedError, check_inside
from rlgrasp.utils import dumps

log = logging.getLogger("rlgrasp.export")

#: Format -> file extension. TorchScript keeps PyTorch's ``.pt`` convention for scripted modules.
FORMATS = {"torchscript": ".pt", "onnx": ".onnx", "pt2": ".pt2"}
ENV_ID = "rlgrasp/PandaGrasp-v0"
#: Default ``tolerance`` per policy kind. A camera policy's convolutions sum thousands of terms, in
#: another order in onnxruntime than in torch: its last bits differ more than an MLP's.
TOLERANCE = {"state": 1e-5, "vision": 1e-4}
#: ``format=folder``: a policy folder (``rlgrasp.policy_file``), data only, read by rlgrasp
#: itself: its actions must equal the checkpoint's exactly unless ``tolerance`` says otherwise.
FOLDER = "folder"
#: An exported file's inputs by name (``observation``, and ``depth``/``rgb`` for a camera policy).
Inputs = dict[str, np.ndarray]


class ExportError(RuntimeError):
    """A user-facing problem with the export's input (printed in one line, exit code 2)."""


@dataclass
class ExportConfig:
    """``rlgrasp-export``'s config (``configs/export.yaml``)."""

    # a run directory (-> checkpoints/<ckpt_kind>.pt), a checkpoint file or a policy folder
    ckpt: str | None = None
    ckpt_kind: str = "best"  # best | last, when ckpt is a run directory
    format: str = "torchscript"  # torchscript | onnx | pt2 | all | folder (model.safetensors + config.json)
    # null: <run>/export/policy.<ext> (folder: <run>/export/policy/). A file path (one format) or a
    # directory (policy.<ext> in it); for format=folder the policy folder itself.
    out: str | None = None
    verify: bool = True  # compare with the checkpoint policy on recorded observations
    verify_obs: int = 1000  # how many observations to record (episodes of the checkpoint's env)
    # Largest allowed |exported action - checkpoint action|; null: TOLERANCE of the policy's kind.
    tolerance: float | None = None
    seed: int = 0  # episode i of the recording is reset with seed + i


def register_export_config() -> None:
    """Register ``ExportConfig`` as ``export_schema`` (idempotent; called by the entry point)."""
    ConfigStore.instance().store(name="export_schema", node=ExportConfig)


__all__ = ["DeployPolicy", "ExportConfig", "ExportError", "deploy_module", "export", "load_exported", "main"]


# --- what goes in -------------------------------------------------------------------------------
def input_specs(spec: dict[str, Any]) -> list[dict[str, Any]]:
    """The exported file's inputs, in its signature's order: name, the env observation entry it is
    fed from (``None``: the whole observation of an env without a camera), dtype, shape."""
    images = image_specs(spec)
    inputs = [
        {
            "name": "observation",
            "env_key": "state" if images else None,
            "dtype": "float32",
            "shape": ["batch", int(spec["obs_dim"])],
        }
    ]
    for key, shape in images.items():
        dtype = "uint8" if key == "rgb" else "float32"
        inputs.append({"name": key, "env_key": key, "dtype": dtype, "shape": ["batch", *map(int, shape)]})
    return inputs


def example_inputs(inputs: list[dict[str, Any]], batch: int = 2) -> dict[str, torch.Tensor]:
    return {i["name"]: torch.zeros(batch, *i["shape"][1:], dtype=getattr(torch, i["dtype"])) for i in inputs}


# --- writing and loading the three formats ------------------------------------------------------
def write_format(module: nn.Module, fmt: str, path: Path, inputs: list[dict[str, Any]]) -> Path:
    """Serialize ``module`` as ``fmt`` to ``path``, with a dynamic batch dimension on every input
    (``inputs``: ``input_specs``)."""
    if fmt not in FORMATS:
        raise ExportError(f"format={fmt}: must be one of {', '.join(FORMATS)} or all")
    with _writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
    example = example_inputs(inputs)
    batch = torch.export.Dim("batch", min=1)
    dynamic = {name: {0: batch} for name in example}
    with warnings.catch_warnings():
        # TorchScript and the dynamic-axes bridge warn about their own deprecation on every call.
        warnings.simplefilter("ignore")
        if fmt == "torchscript":
            scripted = torch.jit.script(module)
            with _writing(path):
                torch.jit.save(scripted, str(path))
        elif fmt == "pt2":
            program = torch.export.export(module, tuple(example.values()), dynamic_shapes=dynamic)
            with _writing(path):
                torch.export.save(program, str(path))
        else:
            _write_onnx(module, example, dynamic, path)
    return path


@contextlib.contextmanager
def _writing(path: Path) -> Iterator[None]:
    """A file system refusing a write (full disk, permissions changed since ``check_request``) is one
    line naming the file, not the writer's traceback (torch's writers raise RuntimeError for it)."""
    try:
        yield
    except (OSError, RuntimeError) as exc:
        raise ExportError(f"cannot write {path}: {str(exc).splitlines()[0]}") from exc


def _write_onnx(
    module: nn.Module, example: dict[str, torch.Tensor], dynamic: dict[str, Any], path: Path
) -> None:
    """The torch.export-based exporter (the legacy TorchScript one is deprecated); needs onnxscript."""
    # The exporter prints its optimization passes and warns about torchvision's ops: not ours.
    for name in ("torch.onnx", "onnxscript", "onnx_ir"):
        logging.getLogger(name).setLevel(logging.ERROR)
    with contextlib.redirect_stdout(io.StringIO()):
        program = torch.onnx.export(
            module,
            tuple(example.values()),
            dynamic_shapes=dynamic,
            input_names=list(example),
            output_names=["action"],
            dynamo=True,
            external_data=False,  # one self-contained file, whatever the model's size
            verbose=False,
        )
        with _writing(path):
            program.save(str(path))


def load_exported(path: str | Path) -> Callable[[np.ndarray | Inputs], np.ndarray]:
    """``f(inputs) -> actions [B, action_dim]`` for a file of any format; ``inputs`` maps each input
    name to its batch (``[B, ...]``, the dtype the file declares); a bare array is ``observation``.

    ONNX goes through onnxruntime, as a deployment would (not through torch).
    """
    path = Path(path)
    if path.suffix == ".onnx":
        import onnxruntime  # lazy: an optional dependency (the export extra), for ONNX files only

        session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        return lambda inputs: session.run(None, _named(inputs))[0]
    if path.suffix == ".pt2":
        module = torch.export.load(str(path)).module()
        names = list(inspect.signature(module.forward).parameters)
    else:
        module = torch.jit.load(str(path), map_location="cpu")
        names = [a.name for a in module.forward.schema.arguments[1:]]  # [0] is self

    def run(inputs: np.ndarray | Inputs) -> np.ndarray:
        named = _named(inputs)
        with torch.no_grad():  # positional, in the file's order: a torch.export module takes no keywords
            return module(*[torch.from_numpy(np.ascontiguousarray(named[n])) for n in names]).numpy()

    return run


def _named(inputs: np.ndarray | Inputs) -> Inputs:
    return dict(inputs) if isinstance(inputs, dict) else {"observation": np.asarray(inputs, np.float32)}


# --- checking against the checkpoint policy ------------------------------------------------------
def make_env(env_cfg: dict[str, Any]) -> Any:
    """The checkpoint's env without rendering (``rlgrasp.envs.factory.env_factory``, as everywhere)."""
    cfg = build_env_cfg(env_cfg)
    cfg["render_mode"] = None
    return env_factory(cfg)()


def record(ckpt: dict[str, Any], n: int, seed: int) -> tuple[Inputs, np.ndarray]:
    """``n`` observations from seeded episodes of the checkpoint's env driven by the checkpoint's
    deterministic policy, as the exported file's inputs (name -> ``[n, ...]``), and that policy's
    actions: evaluation's own ``CheckpointActor``, one observation at a time, so the reference is
    exactly what ``rlgrasp-eval`` would do."""
    actor = CheckpointActor(ckpt, deterministic=True)
    inputs = input_specs(ckpt["spec"])
    env = make_env(ckpt["config"]["env"])
    recorded: dict[str, list[np.ndarray]] = {i["name"]: [] for i in inputs}
    actions = []
    try:
        episode = 0
        while len(actions) < n:
            obs, _ = env.reset(seed=seed + episode)
            actor.reset(seed + episode)
            done = False
            while not done and len(actions) < n:
                action = actor(obs)
                for i in inputs:
                    value = obs[i["env_key"]] if i["env_key"] else obs
                    recorded[i["name"]].append(np.asarray(value, i["dtype"]))
                actions.append(action)
                obs, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
            episode += 1
    finally:
        env.close()
    return {k: np.stack(v) for k, v in recorded.items()}, np.stack(actions).astype(np.float32)


def max_abs_diff(path: Path, observations: Inputs, reference: np.ndarray) -> float:
    """Largest |exported - reference| over all observations, fed one at a time as in deployment (and
    as the reference was computed: a batch sums in another order, differing in the last bits)."""
    policy = load_exported(path)
    exported = np.concatenate(
        [policy({k: v[i : i + 1] for k, v in observations.items()}) for i in range(len(reference))]
    )
    if exported.shape != reference.shape:
        raise ExportError(f"{path}: actions of shape {exported.shape}, expected {reference.shape}")
    return float(np.abs(exported - reference).max())


# --- the JSON beside the file -------------------------------------------------------------------
def action_meaning(env_cfg: dict[str, Any]) -> list[str]:
    """What each action entry does, in the env's units (entries are in [-1, 1], clipped)."""
    control = ControlConfig(**env_setting(env_cfg, "control", {}))
    if control.mode == "ee_delta":
        motion = [f"grasp point d{a} x {control.ee_step} m (world frame)" for a in "xyz"]
        if control.ee_yaw:
            motion.append(f"gripper yaw delta x {control.yaw_step} rad")
    elif control.mode == "joint_delta":
        motion = [f"panda_joint{i} delta x {control.joint_step} rad" for i in range(1, 8)]
    else:
        frac = control.torque_fraction
        motion = [f"panda_joint{i} torque x {frac} of its effort limit" for i in range(1, 8)]
    return [*motion, "finger width target, absolute: -1 closed, +1 open (0.08 m)"]


def versions() -> dict[str, str]:
    names = ("torch", "numpy", "gymnasium", "pybullet", "onnx", "onnxruntime", "rlgrasp")
    return package_versions(names, missing=None)


def describe(ckpt: dict[str, Any], ckpt_path: Path, env: Any) -> dict[str, Any]:
    """Everything a deployment needs to know about the inputs and the action, without rlgrasp."""
    spec, env_cfg = ckpt["spec"], dict(ckpt["config"]["env"])
    env_kwargs = {k: v for k, v in env_cfg.items() if k not in ("_target_", "render_mode")}
    model = ckpt["config"].get("model", {})
    inputs = input_specs(spec)
    normalization = "inside the file: running mean/std of the training observations, " + (
        f"clipped to +-{model.get('obs_clip')}" if model.get("obs_norm", True) else "none"
    )
    return {
        "inputs": inputs,
        # A state policy's one input, under the key earlier files had.
        **({"input": {k: inputs[0][k] for k in ("name", "dtype", "shape")}} if len(inputs) == 1 else {}),
        "output": {"name": "action", "dtype": "float32", "shape": ["batch", spec["action_dim"]]},
        "observation_layout": observation_layout(env, spec),
        **camera_description(env),
        "action_meaning": action_meaning(env_cfg),
        "action_low": list(spec["action_low"]),
        "action_high": list(spec["action_high"]),
        "control_mode": env_setting(env_cfg, "control.mode"),
        "control_hz": round(
            1.0 / (env_setting(env_cfg, "sim.time_step") * env_setting(env_cfg, "sim.substeps"))
        ),
        "normalization": normalization if model.get("obs_norm", True) else "none",
        "deterministic": (
            "tanh of the Gaussian's mean, scaled to the action bounds"
            if squashes(model)
            else "the Gaussian's mean, clipped to the action bounds"
        ),
        "env_id": ENV_ID,
        "env_kwargs": env_kwargs,
        "checkpoint": {
            "path": str(ckpt_path),
            "sha256": digest(ckpt_path),
            "kind": ckpt.get("kind", "state"),
            "frames": ckpt.get("frames"),
            "best_eval_success": ckpt.get("best_eval_success"),
            "experiment_name": ckpt["config"].get("experiment_name"),
            "seed": ckpt["config"].get("seed"),
        },
        "versions": {"export": versions(), "training": ckpt.get("versions", {})},
    }


def digest(path: Path) -> str:
    """The sha256 of a checkpoint file, or of a policy folder's weights then its config."""
    files = [path / WEIGHTS, path / CONFIG] if path.is_dir() else [path]
    sha = hashlib.sha256()
    for file in files:
        sha.update(file.read_bytes())
    return sha.hexdigest()


def observation_layout(env: Any, spec: dict[str, Any]) -> dict[str, list[int]]:
    """Each named part's [start, stop) in the ``observation`` input: the whole state vector, or for
    a camera env its proprioception (``state``) only. An env without named parts: one block."""
    slices = getattr(env.unwrapped, "obs_slices", None)
    if not slices:
        return {"observation": [0, spec["obs_dim"]]}
    if not image_specs(spec):
        return {k: [s.start, s.stop] for k, s in slices.items()}
    layout, start = {}, 0
    for name in PROPRIOCEPTION:  # the order GraspEnv selects them in
        size = slices[name].stop - slices[name].start
        layout[name], start = [start, start + size], start + size
    return layout


def camera_description(env: Any) -> dict[str, Any]:
    """The camera a deployment must reproduce (pose, field of view, clipping) and what the images
    hold; nothing for an env without a camera."""
    camera = getattr(env.unwrapped, "camera", None)
    if camera is None:
        return {}
    s = camera.spec
    pose = {k: [float(x) for x in v] for k, v in s.pose().items()}
    frame = "the hand's frame (z along the fingers)" if s.mount == "wrist" else "the world frame"
    return {
        "camera": {
            "mount": s.mount,
            "modality": s.modality,
            "width": s.width,
            "height": s.height,
            "fov_deg_vertical": s.fov,
            "near": s.near,
            "far": s.far,
            **pose,
            "pose_frame": frame,
        },
        "images": {
            "layout": "channel first, [batch, C, H, W], row 0 at the top",
            "depth": f"float32 metres along the view axis, clipped to [{s.near}, {s.far}]; 0 = no reading "
            f"(a sensor's missing pixel); scaled by 1/{s.far} inside the file",
            "rgb": "uint8 0-255, RGB order; scaled by 1/255 inside the file",
        },
    }


# --- the command ------------------------------------------------------------------------------
def output_paths(fmt: str, out: str | None, ckpt_path: Path) -> dict[str, Path]:
    """Format -> file: ``out`` as a file (one format) or a folder; default ``<run>/export/``.
    ``format=folder``: the policy folder, ``out`` or ``<run>/export/policy/``."""
    if fmt == FOLDER:
        return {FOLDER: Path(out).expanduser() if out else export_dir(ckpt_path) / "policy"}
    formats = list(FORMATS) if fmt == "all" else [fmt]
    if any(f not in FORMATS for f in formats):
        raise ExportError(f"format={fmt}: must be one of {', '.join(FORMATS)}, all or {FOLDER}")
    if out and len(formats) == 1 and Path(out).suffix and not Path(out).expanduser().is_dir():
        path = Path(out).expanduser()
        if path.suffix != FORMATS[fmt]:  # loaders (load_exported, the example) go by the extension
            raise ExportError(f"out={out}: a {fmt} file must end in {FORMATS[fmt]}")
        return {fmt: path}
    folder = Path(out).expanduser() if out else export_dir(ckpt_path)
    return {f: folder / f"policy{FORMATS[f]}" for f in formats}


def export_dir(ckpt_path: Path) -> Path:
    """The default output folder: ``<run>/checkpoints/x.pt`` -> ``<run>/export``; a loose file or a
    policy folder -> ``export/`` beside it; never reached through a link."""
    parent = ckpt_path.absolute().parent
    base = parent.parent if parent.name == "checkpoints" else parent
    folder = base / "export"
    try:
        for path in (ckpt_path, folder):
            check_inside(base, path, f"ckpt={ckpt_path}")
    except ReceivedError as exc:
        raise ExportError(str(exc)) from None
    return folder


def load_source(ckpt: str | None, kind: str) -> tuple[dict[str, Any], Path]:
    """The checkpoint, checked like evaluation checks it (its messages, as ``ExportError``)."""
    if not ckpt:
        raise ExportError("ckpt=<run dir, checkpoint file or policy folder> is required")
    try:
        path = resolve_checkpoint_path(ckpt, kind)
        return load_checked_checkpoint(path), path
    except EvaluationError as exc:
        raise ExportError(str(exc)) from exc


def check_request(cfg: Any, paths: dict[str, Path]) -> None:
    """Everything about the request that can be wrong, before any work: the numbers, the packages
    ONNX needs, and that every file can be written."""
    if cfg.verify and cfg.verify_obs < 1:
        raise ExportError(f"verify_obs={cfg.verify_obs}: must be at least 1 (or verify=false)")
    if cfg.tolerance is not None and not cfg.tolerance >= 0:
        raise ExportError(f"tolerance={cfg.tolerance}: must be >= 0")
    if "onnx" in paths:
        needed = ["onnxscript", *(["onnxruntime"] if cfg.verify else [])]
        missing = [m for m in needed if importlib.util.find_spec(m) is None]
        if missing:
            raise ExportError(f'format=onnx needs {", ".join(missing)}: pip install -e ".[export]"')
    if FOLDER in paths:
        check_folder_request(paths[FOLDER])
    for path in paths.values():
        problem = unwritable(path, folder=FOLDER in paths)
        if problem:
            raise ExportError(f"cannot write {path}: {problem}")


def check_folder_request(folder: Path) -> None:
    """``format=folder``: safetensors installed, and ``out`` new, empty or a policy folder (which is
    replaced): any other folder is the user's, never overwritten."""
    if importlib.util.find_spec("safetensors") is None:
        raise ExportError(f"format={FOLDER} needs the safetensors package: {INSTALL}")
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise ExportError(f"out={folder}: is not a folder (a policy folder is written as a new folder)")
    if folder.is_dir() and any(folder.iterdir()) and not is_policy_folder(folder):
        raise ExportError(
            f"out={folder}: exists and is not a policy folder (no {WEIGHTS} and {CONFIG}); give a new "
            "or empty folder, or a policy folder to replace"
        )


def export(cfg: Any) -> dict[str, dict[str, Any]]:
    """Write the file(s) and their JSON; verify each on recorded observations. Returns, per format,
    the file and the largest action difference (``None`` with ``verify=false``)."""
    ckpt, ckpt_path, paths, info, module = _prepare(cfg)
    kind = "vision" if len(info["inputs"]) > 1 else "state"
    tolerance = TOLERANCE[kind] if cfg.tolerance is None else cfg.tolerance
    results = {}
    with _one_thread():
        recorded = record(ckpt, cfg.verify_obs, cfg.seed) if cfg.verify else None
        for fmt, path in paths.items():
            if fmt == FOLDER:
                limit = 0.0 if cfg.tolerance is None else cfg.tolerance
                results[fmt] = _write_folder(ckpt, ckpt_path, path, info, recorded, limit)
            else:
                results[fmt] = _write_one(module, fmt, path, info, recorded, cfg, tolerance)
    return results


def _write_folder(
    ckpt: dict[str, Any],
    ckpt_path: Path,
    folder: Path,
    info: dict[str, Any],
    recorded: tuple[Inputs, np.ndarray] | None,
    tolerance: float,
) -> dict[str, Any]:
    """The policy folder, written and read back under a temporary name beside ``folder`` (its
    actions compared with the checkpoint's on ``recorded``), then put in place of ``folder``: a
    failed check or write leaves the previous folder as it was and nothing temporary."""
    folder = folder.absolute()
    tmp = folder.with_name(f".{folder.name}.tmp{os.getpid()}")
    old = folder.with_name(f".{folder.name}.old{os.getpid()}")
    try:
        with _writing(folder):
            write_policy_folder(ckpt, tmp, info, ckpt_path, folder.name)
        diff = folder_diff(tmp, *recorded) if recorded else None
        if diff is not None and not diff <= tolerance:
            raise ExportError(
                f"{folder}: the folder's actions differ from the checkpoint's by {diff:.3g} "
                f"> tolerance {tolerance} (nothing was replaced)"
            )
        with _writing(folder):
            if folder.exists():
                os.replace(folder, old)
            os.replace(tmp, folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)
    shown = "not verified" if diff is None else f"max |action diff| {diff:.2e} on {len(recorded[1])} obs"
    log.info("%s: %s (%s)", FOLDER, folder, shown)
    return {"path": str(folder), "json": str(folder / CONFIG), "max_abs_action_diff": diff}


def folder_diff(folder: Path, observations: Inputs, reference: np.ndarray) -> float:
    """Largest |folder policy's action - reference| over the recorded observations: the folder read
    back as any reader reads it (``read_checkpoint``), acting as ``rlgrasp-eval`` acts."""
    try:
        actor = CheckpointActor(read_checkpoint(folder), deterministic=True)
    except CheckpointError as exc:
        raise ExportError(f"the written folder does not read back: {exc}") from exc
    state_key = "state" if len(observations) > 1 else None
    actions = []
    for i in range(len(reference)):
        row = {k: v[i] for k, v in observations.items()}
        obs = {**row, "state": row["observation"]} if state_key else row["observation"]
        actions.append(actor(obs))
    return float(np.abs(np.stack(actions).astype(np.float32) - reference).max())


def _write_one(
    module: nn.Module,
    fmt: str,
    path: Path,
    info: dict[str, Any],
    recorded: tuple[Inputs, np.ndarray] | None,
    cfg: Any,
    tolerance: float,
) -> dict[str, Any]:
    """One format: the file, its JSON, its largest action difference on ``recorded`` (if any).

    Written and verified under a temporary name beside ``path`` (same suffix: the loader goes by
    it), then renamed over it with its JSON: a file that fails its verification, or a write that
    fails, leaves the previous export and its JSON as they were and no temporary file.
    """
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    json_path = path.with_name(path.name + ".json")
    json_tmp = tmp.with_name(tmp.name + ".json")
    try:
        write_format(module, fmt, tmp, info["inputs"])
        diff = max_abs_diff(tmp, *recorded) if recorded else None
        shown = "not verified" if diff is None else f"max |action diff| {diff:.2e} on {cfg.verify_obs} obs"
        if diff is not None and not diff <= tolerance:
            raise ExportError(
                f"{path}: exported actions differ from the checkpoint's by {diff:.3g} "
                f"> tolerance {tolerance} (nothing was replaced)"
            )
        check = {
            "observations": cfg.verify_obs,
            "seed": cfg.seed,
            "max_abs_action_diff": diff,
            "tolerance": tolerance,
        }
        meta = {"format": fmt, "file": path.name, **info, "verification": check if recorded else None}
        with _writing(json_path):
            json_tmp.write_text(dumps(meta))
        os.replace(tmp, path)
        os.replace(json_tmp, json_path)
    finally:
        tmp.unlink(missing_ok=True)
        json_tmp.unlink(missing_ok=True)
    log.info("%s: %s (%s)", fmt, path, shown)
    return {"path": str(path), "json": str(json_path), "max_abs_action_diff": diff}


def _prepare(cfg: Any) -> tuple[dict[str, Any], Path, dict[str, Path], dict[str, Any], nn.Module]:
    """Everything checked before any file is written: the checkpoint, the output paths, the env it
    acts in (layout included); its description and its deployable module."""
    if cfg.ckpt_kind not in CKPT_KINDS:
        raise ExportError(f"ckpt_kind={cfg.ckpt_kind}: must be one of {', '.join(CKPT_KINDS)}")
    ckpt, ckpt_path = load_source(cfg.ckpt, cfg.ckpt_kind)
    paths = output_paths(cfg.format, cfg.out, ckpt_path)
    check_request(cfg, paths)
    try:
        env = make_env(ckpt["config"]["env"])
    except ENV_ERRORS as exc:
        raise ExportError(f"cannot build the env of checkpoint {ckpt_path}: {exc}") from exc
    try:
        check_layout(ckpt["spec"], env, f"checkpoint {ckpt_path}")
        info = describe(ckpt, ckpt_path.resolve(), env)
    except EvaluationError as exc:
        raise ExportError(str(exc)) from exc
    finally:
        env.close()
    try:
        module = deploy_module(ckpt)
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise ExportError(f"corrupt checkpoint: {ckpt_path}: the policy cannot be rebuilt ({exc})") from exc
    return ckpt, ckpt_path, paths, info, module


@contextlib.contextmanager
def _one_thread() -> Iterator[None]:
    """One torch thread while recording and verifying: one observation at a time, as a robot runs it
    (and as evaluation's workers do); threads only add contention at batch one."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def run(cfg: Any) -> dict[str, dict[str, Any]]:
    """``export`` with a bad input ending in one line on stderr and exit code 2."""
    try:
        return export(cfg)
    except ExportError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


def main() -> None:
    """Console entry point ``rlgrasp-export`` (same as ``python scripts/export.py``)."""
    register_export_config()
    logging.basicConfig(level=logging.INFO, format="[%(levelname)s] %(message)s")
    hydra_main = hydra.main(config_path=CONFIG_DIR, config_name="export", version_base="1.3")(run)
    entry_point("export")(hydra_main)()
