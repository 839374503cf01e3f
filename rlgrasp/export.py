"""Export a trained policy for deployment: one file, raw observation in, deterministic action out.

The checkpoint's actor is a TorchRL ``ProbabilisticActor`` reading and writing tensordicts, which no
deployment runtime understands. ``DeployPolicy`` is the same computation as a plain ``nn.Module``
(running-mean/std normalizer -> MLP -> loc -> the TanhNormal's deterministic sample, i.e. a clamped
tanh affinely scaled to the action bounds), so TorchScript, ONNX and ``torch.export`` can all
serialize it. Every export is checked against the checkpoint policy on observations recorded from
env rollouts, and a JSON file beside it says what the vectors mean.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import io
import json
import logging
import re
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
from rlgrasp.envs.factory import env_factory
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
from rlgrasp.overrides import entry_point, unwritable
from rlgrasp.train.checkpoint import package_versions, policy_from_checkpoint

log = logging.getLogger("rlgrasp.export")

#: Format -> file extension. TorchScript keeps PyTorch's ``.pt`` convention for scripted modules.
FORMATS = {"torchscript": ".pt", "onnx": ".onnx", "pt2": ".pt2"}
ENV_ID = "rlgrasp/PandaGrasp-v0"


class ExportError(RuntimeError):
    """A user-facing problem with the export's input (printed in one line, exit code 2)."""


@dataclass
class ExportConfig:
    """``rlgrasp-export``'s config (``configs/export.yaml``)."""

    ckpt: str | None = None  # a run directory (-> checkpoints/<ckpt_kind>.pt) or a checkpoint file
    ckpt_kind: str = "best"  # best | last, when ckpt is a run directory
    format: str = "torchscript"  # torchscript | onnx | pt2 | all
    # null: <run>/export/policy.<ext>. A file path (one format) or a directory (policy.<ext> in it).
    out: str | None = None
    verify: bool = True  # compare with the checkpoint policy on recorded observations
    verify_obs: int = 1000  # how many observations to record (episodes of the checkpoint's env)
    tolerance: float = 1e-5  # largest allowed |exported action - checkpoint action|
    seed: int = 0  # episode i of the recording is reset with seed + i


def register_export_config() -> None:
    """Register ``ExportConfig`` as ``export_schema`` (idempotent; called by the entry point)."""
    ConfigStore.instance().store(name="export_schema", node=ExportConfig)


# --- the deployable module ----------------------------------------------------------------------
class DeployPolicy(nn.Module):
    """Raw observation ``[..., obs_dim]`` float32 -> deterministic action ``[..., action_dim]``.

    Matches ``TanhNormal.deterministic_sample`` of the training actor exactly: tanh of the MLP's
    loc clamped to +-(1 - float32 resolution) (TorchRL's safe tanh), then scaled to the bounds.
    """

    def __init__(self, net: nn.Module, low: torch.Tensor, high: torch.Tensor) -> None:
        super().__init__()
        norm = net.norm
        self.normalize = bool(norm.enabled)
        self.clip, self.eps = float(norm.clip), float(norm.eps)
        self.register_buffer("mean", norm.mean.detach().clone().float())
        self.register_buffer("var", norm.var.detach().clone().float())
        # A plain Sequential of the same layers (TorchRL's MLP.forward is not scriptable).
        self.mlp = nn.Sequential(*[m for m in net.mlp.children()])
        low, high = torch.as_tensor(low, dtype=torch.float32), torch.as_tensor(high, dtype=torch.float32)
        self.rescale = bool((low != -1).any() or (high != 1).any())
        self.register_buffer("mid", (high + low) / 2)
        self.register_buffer("half_range", (high - low) / 2)
        self.lim = 1.0 - float(torch.finfo(torch.float32).resolution)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        x = observation
        if self.normalize:
            # The same operations in the same order as RunningNorm: bit-identical inputs to the MLP.
            x = ((x - self.mean) / torch.sqrt(self.var + self.eps)).clamp(-self.clip, self.clip)
        y = torch.tanh(self.mlp(x)).clamp(-self.lim, self.lim)
        if self.rescale:
            y = self.mid + self.half_range * y
        return y


def deploy_module(ckpt: dict[str, Any]) -> DeployPolicy:
    """The ``DeployPolicy`` of a loaded checkpoint, built from the very modules training uses."""
    actor = policy_from_checkpoint(ckpt, "cpu")
    net = actor.module[0].module
    spec = ckpt["spec"]
    return DeployPolicy(net, torch.as_tensor(spec["action_low"]), torch.as_tensor(spec["action_high"])).eval()


# --- writing and loading the three formats ------------------------------------------------------
def write_format(module: DeployPolicy, fmt: str, path: Path, obs_dim: int) -> Path:
    """Serialize ``module`` as ``fmt`` to ``path``, with a dynamic batch dimension."""
    if fmt not in FORMATS:
        raise ExportError(f"format={fmt}: must be one of {', '.join(FORMATS)} or all")
    with _writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
    example = torch.zeros(2, obs_dim)
    with warnings.catch_warnings():
        # TorchScript and the dynamic-axes bridge warn about their own deprecation on every call.
        warnings.simplefilter("ignore")
        if fmt == "torchscript":
            scripted = torch.jit.script(module)
            with _writing(path):
                torch.jit.save(scripted, str(path))
        elif fmt == "pt2":
            batch = torch.export.Dim("batch", min=1)
            program = torch.export.export(module, (example,), dynamic_shapes={"observation": {0: batch}})
            with _writing(path):
                torch.export.save(program, str(path))
        else:
            _write_onnx(module, example, path)
    return path


@contextlib.contextmanager
def _writing(path: Path) -> Iterator[None]:
    """A file system refusing a write (full disk, permissions changed since ``check_request``) is one
    line naming the file, not the writer's traceback (torch's writers raise RuntimeError for it)."""
    try:
        yield
    except (OSError, RuntimeError) as exc:
        raise ExportError(f"cannot write {path}: {str(exc).splitlines()[0]}") from exc


def _write_onnx(module: DeployPolicy, example: torch.Tensor, path: Path) -> None:
    """The torch.export-based exporter (the legacy TorchScript one is deprecated); needs onnxscript."""
    batch = torch.export.Dim("batch", min=1)
    # The exporter prints its optimization passes and warns about torchvision's ops: not ours.
    for name in ("torch.onnx", "onnxscript", "onnx_ir"):
        logging.getLogger(name).setLevel(logging.ERROR)
    with contextlib.redirect_stdout(io.StringIO()):
        program = torch.onnx.export(
            module,
            (example,),
            dynamic_shapes={"observation": {0: batch}},
            input_names=["observation"],
            output_names=["action"],
            dynamo=True,
            external_data=False,  # one self-contained file, whatever the model's size
            verbose=False,
        )
        with _writing(path):
            program.save(str(path))


def load_exported(path: str | Path) -> Callable[[np.ndarray], np.ndarray]:
    """``f(obs [B, obs_dim] float32) -> actions [B, action_dim]`` for a file of any format.

    ONNX goes through onnxruntime, as a deployment would (not through torch).
    """
    path = Path(path)
    if path.suffix == ".onnx":
        import onnxruntime  # lazy: an optional dependency (the export extra), for ONNX files only

        session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        return lambda obs: session.run(None, {"observation": np.asarray(obs, np.float32)})[0]
    if path.suffix == ".pt2":
        module = torch.export.load(str(path)).module()
    else:
        module = torch.jit.load(str(path), map_location="cpu")

    def run(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return module(torch.as_tensor(np.asarray(obs, np.float32))).numpy()

    return run


# --- checking against the checkpoint policy ------------------------------------------------------
def make_env(env_cfg: dict[str, Any]) -> Any:
    """The checkpoint's env without rendering (``rlgrasp.envs.factory.env_factory``, as everywhere)."""
    cfg = build_env_cfg(env_cfg)
    cfg["render_mode"] = None
    return env_factory(cfg)()


def record(ckpt: dict[str, Any], n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` observations from seeded episodes of the checkpoint's env driven by the checkpoint's
    deterministic policy, and that policy's actions: evaluation's own ``CheckpointActor``, one
    observation at a time, so the reference is exactly what ``rlgrasp-eval`` would do."""
    actor = CheckpointActor(ckpt, deterministic=True)
    env = make_env(ckpt["config"]["env"])
    observations, actions = [], []
    try:
        episode = 0
        while len(observations) < n:
            obs, _ = env.reset(seed=seed + episode)
            actor.reset(seed + episode)
            done = False
            while not done and len(observations) < n:
                action = actor(obs)
                observations.append(np.asarray(obs, np.float32))
                actions.append(action)
                obs, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
            episode += 1
    finally:
        env.close()
    return np.stack(observations), np.stack(actions).astype(np.float32)


def max_abs_diff(path: Path, observations: np.ndarray, reference: np.ndarray) -> float:
    """Largest |exported - reference| over all observations, fed one at a time as in deployment (and
    as the reference was computed: a batch sums in another order, differing in the last bits)."""
    policy = load_exported(path)
    exported = np.concatenate([policy(obs[None]) for obs in observations])
    if exported.shape != reference.shape:
        raise ExportError(f"{path}: actions of shape {exported.shape}, expected {reference.shape}")
    return float(np.abs(exported - reference).max())


# --- the JSON beside the file -------------------------------------------------------------------
def action_meaning(env_cfg: dict[str, Any]) -> list[str]:
    """What each action entry does, in the env's units (entries are in [-1, 1], clipped)."""
    mode = env_cfg.get("control_mode", "ee_delta")
    if mode == "ee_delta":
        step = env_cfg.get("ee_step", 0.04)
        motion = [f"grasp point d{a} x {step} m (world frame)" for a in "xyz"]
        if env_cfg.get("ee_yaw"):
            motion.append(f"gripper yaw delta x {env_cfg.get('yaw_step', 0.2)} rad")
    elif mode == "joint_delta":
        motion = [f"panda_joint{i} delta x {env_cfg.get('joint_step', 0.05)} rad" for i in range(1, 8)]
    else:
        frac = env_cfg.get("torque_fraction", 0.3)
        motion = [f"panda_joint{i} torque x {frac} of its effort limit" for i in range(1, 8)]
    return [*motion, "finger width target, absolute: -1 closed, +1 open (0.08 m)"]


def versions() -> dict[str, str]:
    names = ("torch", "numpy", "gymnasium", "pybullet", "onnx", "onnxruntime", "rlgrasp")
    return package_versions(names, missing=None)


def describe(ckpt: dict[str, Any], ckpt_path: Path, env: Any) -> dict[str, Any]:
    """Everything a deployment needs to know about the vectors, without rlgrasp installed."""
    spec, env_cfg = ckpt["spec"], dict(ckpt["config"]["env"])
    env_kwargs = {k: v for k, v in env_cfg.items() if k not in ("_target_", "render_mode")}
    model = ckpt["config"].get("model", {})
    return {
        "input": {"name": "observation", "dtype": "float32", "shape": ["batch", spec["obs_dim"]]},
        "output": {"name": "action", "dtype": "float32", "shape": ["batch", spec["action_dim"]]},
        # Envs without named parts (stand-ins, your own): one block.
        "observation_layout": {k: [s.start, s.stop] for k, s in getattr(env, "obs_slices", {}).items()}
        or {"observation": [0, spec["obs_dim"]]},
        "action_meaning": action_meaning(env_cfg),
        "action_low": list(spec["action_low"]),
        "action_high": list(spec["action_high"]),
        "control_mode": env_cfg.get("control_mode"),
        "control_hz": round(1.0 / (env_cfg.get("time_step", 1 / 240) * env_cfg.get("substeps", 12))),
        "normalization": "inside the file: running mean/std of the training observations, "
        f"clipped to +-{model.get('obs_clip')}" if model.get("obs_norm", True) else "none",
        "deterministic": "tanh of the Gaussian's mean, scaled to the action bounds",
        "env_id": ENV_ID,
        "env_kwargs": env_kwargs,
        "checkpoint": {
            "path": str(ckpt_path),
            "sha256": hashlib.sha256(ckpt_path.read_bytes()).hexdigest(),
            "frames": ckpt.get("frames"),
            "best_eval_success": ckpt.get("best_eval_success"),
            "experiment_name": ckpt["config"].get("experiment_name"),
            "seed": ckpt["config"].get("seed"),
        },
        "versions": {"export": versions(), "training": ckpt.get("versions", {})},
    }


# --- the command ------------------------------------------------------------------------------
def output_paths(fmt: str, out: str | None, ckpt_path: Path) -> dict[str, Path]:
    """Format -> file: ``out`` as a file (one format) or a folder; default ``<run>/export/``."""
    formats = list(FORMATS) if fmt == "all" else [fmt]
    if any(f not in FORMATS for f in formats):
        raise ExportError(f"format={fmt}: must be one of {', '.join(FORMATS)} or all")
    if out and len(formats) == 1 and Path(out).suffix and not Path(out).expanduser().is_dir():
        path = Path(out).expanduser()
        if path.suffix != FORMATS[fmt]:  # loaders (load_exported, the example) go by the extension
            raise ExportError(f"out={out}: a {fmt} file must end in {FORMATS[fmt]}")
        return {fmt: path}
    if out:
        folder = Path(out).expanduser()
    else:  # <run>/checkpoints/x.pt -> <run>/export; a loose file -> export/ beside it
        parent = ckpt_path.resolve().parent
        folder = (parent.parent if parent.name == "checkpoints" else parent) / "export"
    return {f: folder / f"policy{FORMATS[f]}" for f in formats}


def load_source(ckpt: str | None, kind: str) -> tuple[dict[str, Any], Path]:
    """The checkpoint, checked like evaluation checks it (its messages, as ``ExportError``)."""
    if not ckpt:
        raise ExportError("ckpt=<run dir or checkpoint file> is required")
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
    if not cfg.tolerance >= 0:
        raise ExportError(f"tolerance={cfg.tolerance}: must be >= 0")
    if "onnx" in paths:
        needed = ["onnxscript", *(["onnxruntime"] if cfg.verify else [])]
        missing = [m for m in needed if importlib.util.find_spec(m) is None]
        if missing:
            raise ExportError(f"format=onnx needs {', '.join(missing)}: pip install -e \".[export]\"")
    for path in paths.values():
        problem = unwritable(path)
        if problem:
            raise ExportError(f"cannot write {path}: {problem}")


def export(cfg: Any) -> dict[str, dict[str, Any]]:
    """Write the file(s) and their JSON; verify each on recorded observations. Returns, per format,
    the file and the largest action difference (``None`` with ``verify=false``)."""
    if cfg.ckpt_kind not in CKPT_KINDS:
        raise ExportError(f"ckpt_kind={cfg.ckpt_kind}: must be one of {', '.join(CKPT_KINDS)}")
    ckpt, ckpt_path = load_source(cfg.ckpt, cfg.ckpt_kind)
    paths = output_paths(cfg.format, cfg.out, ckpt_path)
    check_request(cfg, paths)
    module = deploy_module(ckpt)
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
    observations = reference = None
    if cfg.verify:
        observations, reference = record(ckpt, cfg.verify_obs, cfg.seed)
    results = {}
    for fmt, path in paths.items():
        write_format(module, fmt, path, ckpt["spec"]["obs_dim"])
        diff = max_abs_diff(path, observations, reference) if cfg.verify else None
        check = {"observations": cfg.verify_obs, "seed": cfg.seed, "max_abs_action_diff": diff}
        meta = {"format": fmt, "file": path.name, **info, "verification": check if cfg.verify else None}
        json_path = path.with_name(path.name + ".json")
        json_path.write_text(_dumps(meta))
        results[fmt] = {"path": str(path), "json": str(json_path), "max_abs_action_diff": diff}
        shown = "not verified" if diff is None else f"max |action diff| {diff:.2e} on {cfg.verify_obs} obs"
        log.info("%s: %s (%s)", fmt, path, shown)
        if diff is not None and not diff <= cfg.tolerance:
            raise ExportError(f"{path}: exported actions differ from the checkpoint's by {diff:.3g} "
                              f"> tolerance {cfg.tolerance}")
    return results


def _dumps(meta: dict[str, Any]) -> str:
    """Indented JSON with short lists on one line (the layout stays readable)."""
    text = json.dumps(meta, indent=2)
    return re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text) + "\n"


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
