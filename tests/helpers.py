"""Helpers shared by several test modules: runs and checkpoints built without training, files that
entry points must refuse, running an entry point in-process, and what a run's seed decides.

Fixtures shared by modules live in ``conftest.py``; starting processes in ``procs.py``; stand-in envs
in ``standins.py``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import runpy
import sys
from collections.abc import Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensordict import TensorDict

from rlgrasp import demo
from rlgrasp.algos.ppo.schema import PPOConfig
from rlgrasp.compose import compose_train
from rlgrasp.demos.dataset import layout_of, write_demos
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.legacy import nest_algo
from rlgrasp.models.cnn import actor_norm, build_vision_actor
from rlgrasp.models.spec import vision_spec
from rlgrasp.policy_file import CHECKPOINT_FORMAT, load_checkpoint, read_checkpoint
from rlgrasp.train.loop import Trainer, train

ROOT = Path(__file__).resolve().parents[1]


def ppo_algo(**keys: Any) -> Any:
    """PPO's ``algo`` node with ``keys`` over the schema's defaults, each named by its leaf
    (``lr=1e-3`` sets ``optim.lr``, ``rnd_coeff`` ``terms.rnd.coeff``: ``rlgrasp.legacy.ALGO_KEYS``),
    so that a unit test of the update reads as a list of the settings it varies."""
    return OmegaConf.merge(OmegaConf.structured(PPOConfig), nest_algo({"name": "ppo", **keys}))


# --- runs and checkpoints ------------------------------------------------------------------------
def make_run(
    tmp: Path, frames: int = 4096, obs_dim: int | None = None, overrides: tuple[str, ...] = ()
) -> Path:
    """A run directory whose checkpoints the training code wrote (random weights, fitted normalizer,
    ``frames`` frames); ``obs_dim`` replaces the recorded observation size (a mismatched checkpoint),
    ``overrides`` are the training config's."""
    run = tmp / "run"
    over = ["model.hidden_sizes=[16,16]", "logger=none", "experiment_name=unit", "seed=3", *overrides]
    cfg = compose_train([f"paths.output_dir={run}", *over])
    trainer = Trainer(cfg)
    trainer.parts.norm.update(torch.randn(64, trainer.parts.spec["obs_dim"]) * 0.3)
    trainer.frames, trainer.algo.updates = frames, 2
    if obs_dim is not None:
        trainer.parts.spec["obs_dim"] = obs_dim
    trainer.save(is_best=True)
    trainer.logger.close()
    return run


TEACHER = ROOT / "policies" / "grasp_ppo.pt"  # a joint_delta state policy: 49 values = the privileged state
#: The camera student's model (``make_student``'s default).
STUDENT_MODEL = {
    "hidden_sizes": [32, 32],
    "activation": "elu",
    "channels": [8, 16, 16],
    "image_features": 32,
    "init_log_std": -0.5,
    "min_std": 0.05,
    "obs_norm": True,
    "obs_clip": 10.0,
}


def make_student(
    tmp: Path,
    modality: str = "depth",
    mount: str = "wrist",
    visual: str = "default",
    spread: bool = True,
    name: str = "student.pt",
    teacher: str | None = str(TEACHER),
    model: dict | None = None,
) -> Path:
    """A camera checkpoint laid out as ``Distiller.save`` writes it. ``spread``: weights that send
    the actions over the whole box (a fresh actor acts near zero, which would hide a wrong squashing
    or a wrong image scaling)."""
    defaults = asdict(EnvConfig())
    env_cfg = {
        **defaults,
        "control": {**defaults["control"], "mode": "joint_delta"},
        "camera": {"mount": mount, "modality": modality},
        "sim": {**defaults["sim"], "visual": visual},
    }
    spec = vision_spec(env_factory(env_cfg))
    torch.manual_seed(0)
    model = model or STUDENT_MODEL
    actor = build_vision_actor(spec, OmegaConf.create(model))
    actor_norm(actor).update(torch.randn(256, spec["obs_dim"]) * 0.5 + 0.1)
    if spread:  # unit-gain layers, the last one 8x: actions at the bounds on some entries
        gen = torch.Generator().manual_seed(1)
        weights = [(k, v) for k, v in actor.named_parameters() if k.endswith("weight") and v.dim() >= 2]
        with torch.no_grad():
            for i, (_, value) in enumerate(weights):
                gain = 8.0 if i == len(weights) - 1 else 1.0
                value.copy_(torch.randn(value.shape, generator=gen) * gain / value[0].numel() ** 0.5)
    ckpt = {
        "format": CHECKPOINT_FORMAT,
        "kind": "vision",
        "actor": actor.state_dict(),
        "spec": spec,
        "config": {
            "env": env_cfg,
            "model": model,
            "algo": {"name": "dagger", "teacher": teacher},
            "experiment_name": "student",
            "seed": 0,
        },
        "frames": 1234,
        "last_eval": None,
        "versions": {},
        "run_dir": str(tmp),
    }
    path = tmp / name
    torch.save(ckpt, path)
    return path


# --- files an entry point must refuse ------------------------------------------------------------
def demo_env_cfg(control_mode: str = "ee_delta", *overrides: str) -> dict:
    """The default training config's env section with ``control_mode`` (and ``overrides``), resolved."""
    cfg = compose_train([f"env.control.mode={control_mode}", "paths.output_dir=.", *overrides])
    return OmegaConf.to_container(cfg.env, resolve=True)


def demo_files(root: Path) -> dict[str, str]:
    """Demonstration files without recording: one of another control mode, one with no episode,
    one seen by the wrist depth camera from 5 cm behind the hand (another view than ``wrist_depth``'s)."""
    out = {}
    for name, mode, kept, *overrides in (
        ("foreign_demos", "joint_delta", 3),
        ("empty_demos", "ee_delta", 0),
        ("behind_demos", "ee_delta", 3, "cameras=wrist_depth_behind", "model=cnn"),
    ):
        target = root / name / "demos"
        if not target.exists():
            env_cfg = demo_env_cfg(mode, *overrides)
            env = env_factory(env_cfg)()
            layout = layout_of(env, env_cfg)
            env.close()
            frames = TensorDict({"observation": torch.zeros(2, layout["obs_dim"])}, [2])
            write_demos(root / name, frames, {**layout, "summary": {"kept": kept}})
        out[name] = str(target)
    return out


def bad_input_files(root: Path) -> dict[str, str]:
    """Camera checkpoints for tests/test_bad_input.py: a good one, one whose recorded teacher is
    gone, one whose spec asks for images its env does not give."""
    folder = root / "vision"
    folder.mkdir(exist_ok=True)
    student = make_student(folder, spread=False)
    orphan = make_student(folder, spread=False, name="orphan.pt", teacher=str(folder / "moved.pt"))
    mismatched = make_student(folder, spread=False, name="mismatched.pt")
    ckpt = torch.load(mismatched, weights_only=True)
    ckpt["spec"]["images"] = {"rgb": [3, 64, 64]}
    torch.save(ckpt, mismatched)
    return {
        "student": str(student),
        "orphan": str(orphan),
        "mismatched": str(mismatched),
        "teacher": str(TEACHER),
    }


# --- entry points in-process ---------------------------------------------------------------------
#: What PyBullet prints on stderr when it is imported, whatever the command: not one of our lines.
PYBULLET_BANNER = "pybullet build time:"
SCRIPTS = {
    "train": "train.py",
    "train_sac": "train.py",
    "eval": "evaluate.py",
    "export": "export.py",
    "enjoy": "enjoy.py",
    "sweep": "sweep.py",
    "demos": "demos.py",
    "report": "report.py",
}


def our_lines(stderr: str) -> list[str]:
    """The non-empty lines of ``stderr`` without PyBullet's import banner."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith(PYBULLET_BANNER)]


@contextlib.contextmanager
def no_display() -> Iterator[None]:
    """rlgrasp-enjoy as on a headless machine: its checks must not need the GUI."""
    saved = {k: os.environ.pop(k) for k in ("DISPLAY", "WAYLAND_DISPLAY") if k in os.environ}
    try:
        yield
    finally:
        os.environ.update(saved)


def run_entry(entry: str, argv: list[str], cwd: Path) -> int:
    """One entry point with ``argv`` in this process, as its command would run it; the exit code."""
    script = str(ROOT / "scripts" / SCRIPTS[entry]) if entry in SCRIPTS else "rlgrasp-demo"
    old_argv, old_cwd = sys.argv, Path.cwd()
    sys.argv = [script, *argv]
    os.chdir(cwd)
    try:
        with no_display():
            if entry == "demo":
                demo.main()
            else:
                runpy.run_path(script, run_name="__main__")
        return 0
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 1
    finally:
        sys.argv = old_argv
        os.chdir(old_cwd)
        GlobalHydra.instance().clear()
        for handler in logging.getLogger().handlers[:]:
            logging.getLogger().removeHandler(handler)


# --- what a training run logs and what its seed decides ------------------------------------------
#: A PPO run in-process (collector=single) on a few hundred frames.
SMOKE_IN_PROCESS = [
    "experiment=smoke",
    "logger=none",
    "collector=single",
    "collector.envs_per_worker=2",
    "collector.steps_per_env=64",
    "algo.optim.minibatch_size=64",
    "total_frames=256",
    "eval.interval_frames=0",
    "eval.episodes=1",
    "eval.final_episodes=1",
    "eval.num_envs=1",
    "checkpoint.interval_frames=128",
    "env.task.reward=sparse",
    "device=cpu",
]
#: Tags that measure the wall clock, not the run.
WALL_CLOCK = ("charts/SPS", "time/")


def logged_scalars(trainer: Trainer) -> dict[str, list[float]]:
    """Every scalar the trainer logs from now on, by name."""
    seen: dict[str, list[float]] = {}
    inner = trainer.logger.scalars

    def scalars(metrics, step):
        for k, v in metrics.items():
            seen.setdefault(k, []).append(float(v))
        return inner(metrics, step)

    trainer.logger.scalars = scalars
    return seen


def tensorboard_scalars(run_dir: Path) -> EventAccumulator:
    """The scalars a run wrote to its ``tensorboard`` folder, loaded."""
    acc = EventAccumulator(str(run_dir / "tensorboard"), size_guidance={"scalars": 0})
    acc.Reload()
    return acc


def run_record(run_dir: Path, user: dict[str, Any] | None = None) -> dict[str, Any]:
    """What a run's seed decides: every curve but the wall-clock ones, the checkpoints it wrote and
    their frames, the final evaluation and the final weights. Floats as hex: equal means bit-identical.
    ``user``: the config the run was trained with (its own env class is read back by naming it)."""
    acc = tensorboard_scalars(run_dir)
    curves = {
        tag: [(e.step, float(e.value).hex()) for e in acc.Scalars(tag)]
        for tag in acc.Tags()["scalars"]
        if not tag.startswith(WALL_CLOCK)
    }
    files = sorted((run_dir / "checkpoints").glob("*.pt"))
    ckpts = {p.name: read_checkpoint(p, user=user)["frames"] for p in files}
    last = load_checkpoint(run_dir, user=user)
    final_eval = {k: float(v).hex() for k, v in last["last_eval"].items()}
    weights = {k: v.numpy().tobytes() for k, v in last["actor"].items()}
    return {"curves": curves, "checkpoints": ckpts, "final_eval": final_eval, "weights": weights}


def record_differences(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """Where two records differ: a curve's tag, ``checkpoints``, ``final_eval`` or a weight's name."""
    out = [part for part in ("checkpoints", "final_eval") if a[part] != b[part]]
    for part in ("curves", "weights"):
        out += [key for key in sorted(set(a[part]) | set(b[part])) if a[part].get(key) != b[part].get(key)]
    return out


def train_twice(
    train_cfg, tmp_path: Path, *overrides: str, env_target: str | None = None
) -> list[dict[str, Any]]:
    """The smoke experiment with ``overrides`` trained twice (``train_cfg`` is the fixture), and the
    record of each run; ``env_target`` replaces the env's ``_target_``."""
    records = []
    for name in ("first", "second"):
        cfg = train_cfg("experiment=smoke", *overrides, run_dir=tmp_path / name)
        if env_target:
            cfg.env = OmegaConf.merge(OmegaConf.to_container(cfg.env), {"_target_": env_target})
        train(cfg)
        records.append(run_record(tmp_path / name, OmegaConf.to_container(cfg)))
    return records
