"""A received file is data (``rlgrasp.received``), tried at random: payloads put at random places of
the shipped policies, a fresh full checkpoint, a recorded demonstrations folder and a SAC run's replay
folder, each run through every reader's load-and-build path in this process. Whatever a reader makes
of it, no file outside its own output folder appears, changes or disappears, no environment value is
printed, and a refusal is one line of one of rlgrasp's error types (anything else is a traceback).

Hundreds of cases in the quick set, thousands with ``-m full``. The payloads: ``_target_``/``_args_``/
``_partial_`` nodes, interpolations, dotted keys, older-format factory keys, rlgrasp's own classes in
the wrong node, a logger with an endpoint, non-mapping nodes, symlinks out of a folder, truncated files,
oversize or wrong shapes and dtypes, NaN tensors.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import importlib.util
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import torch
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.algos.sac.replay_files import ReplayFiles
from rlgrasp.compose import compose_config, compose_train
from rlgrasp.config import ConfigError
from rlgrasp.demos.dataset import load_demos
from rlgrasp.evaluation.report import load_runs
from rlgrasp.evaluation.source import EvaluationError, prepare
from rlgrasp.evaluation.teacher import prepare_teacher
from rlgrasp.export import ExportError, load_source, output_paths
from rlgrasp.policy_file import CheckpointError, load_checkpoint, read_checkpoint
from rlgrasp.received import PARTS, ReceivedError
from rlgrasp.train.checkpoint import save_checkpoint
from rlgrasp.train.loop import Trainer
from rlgrasp.train.resume import prepare_run
from rlgrasp.train.warm_start import warm_start
from rlgrasp.vision.dagger import load_teacher

ROOT = Path(__file__).resolve().parents[1]
SECRET_VAR, SECRET = "RLGRASP_FUZZ_SECRET", "s3cr3t-value-4f1e"
#: What a reader may raise for a file it refuses: rlgrasp's own one-line errors (ValueError covers
#: ReceivedError, CheckpointError, ConfigError, DemoError, ReplayError, ExportError's base is checked).
REFUSALS = (ReceivedError, CheckpointError, ConfigError, EvaluationError, ExportError, SystemExit)
#: FULL: the config cases of CI's complete suite, cut from 2,500 when this one test, CI's longest,
#: brought CI near its time limit on a slower machine; the quick set's run on every change.
QUICK, FULL = 250, 1500
#: No "explain" phase: it reruns a failing case hundreds of times to say which lines only failures ran.
PHASES = (Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink)
FOLDER_QUICK, FOLDER_FULL = 300, 3000


# --- the artefacts, built once -----------------------------------------------------------------
@dataclass
class Bases:
    root: Path
    checkpoints: dict[str, dict[str, Any]]  # name -> the raw dict (torch.load, weights only)
    run: Path  # a fresh full run directory (checkpoints/last.pt, .hydra/config.yaml)
    demos: Path  # a recorded demonstrations folder (``<out>/demos``)
    layout: dict[str, Any]
    train_cfg: Any
    resume_cfg: Any
    replay: Path  # a run directory with a SAC replay folder


@pytest.fixture(scope="module")
def bases(tmp_path_factory) -> Bases:
    root = tmp_path_factory.mktemp("bases")
    shipped = {p.stem: torch.load(p, weights_only=True) for p in sorted((ROOT / "policies").glob("*.pt"))}
    run = root / "run"
    train_cfg = compose_train(["experiment=smoke", "logger=none", f"paths.output_dir={run}"])
    trainer = Trainer(train_cfg)
    trainer.save()
    trainer.logger.close()
    (run / ".hydra").mkdir(exist_ok=True)
    (run / ".hydra" / "config.yaml").write_text(OmegaConf.to_yaml(train_cfg))
    fresh = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    from rlgrasp.demos.cli import record_demos
    from tests.test_received_files import _layout

    record_demos(compose_config("demos", ["episodes=1", f"out={root / 'rec'}", "workers=1", "keep=all"]))
    replay = root / "sac_run"
    files = ReplayFiles(replay)  # the files a SAC run writes beside its checkpoints, as it writes them
    for n in (16, 16, 8):
        files.write(_transitions(n, fresh["spec"]["obs_dim"], fresh["spec"]["action_dim"]))
    return Bases(
        root=root,
        checkpoints={**shipped, "fresh": fresh},
        run=run,
        demos=root / "rec" / "demos",
        layout=_layout(),
        train_cfg=train_cfg,
        resume_cfg=compose_train(["experiment=smoke", "logger=none", "paths.output_dir=."]),
        replay=replay,
    )


def _transitions(n: int, obs: int, act: int) -> TensorDict:
    return TensorDict(
        {
            "observation": torch.randn(n, obs),
            "action": torch.rand(n, act),
            "next": {
                "observation": torch.randn(n, obs),
                "reward": torch.randn(n, 1),
                "done": torch.zeros(n, 1),
            },
        },
        batch_size=[n],
    )


# --- the sandbox each case runs in -------------------------------------------------------------
@contextlib.contextmanager
def sandbox() -> Iterator[Path]:
    """A fresh folder, the working directory while the case runs, holding ``victims/`` (a file that
    must not change, a place where nothing may appear) and ``out/`` (the readers' output folder)."""
    old = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="fuzz_") as tmp:
        box = Path(tmp)
        (box / "victims").mkdir()
        (box / "victims" / "keep.txt").write_bytes(b"k" * 4096)
        (box / "out").mkdir()
        os.environ[SECRET_VAR] = SECRET
        os.chdir(box)
        try:
            yield box
        finally:
            os.chdir(old)
            os.environ.pop(SECRET_VAR, None)


def snapshot(box: Path) -> dict[str, Any]:
    """Every entry under ``box`` but ``out/``, with what it is and holds (links not followed)."""
    found = {}
    for folder, dirs, files in os.walk(box, followlinks=False):
        rel = Path(folder).relative_to(box)
        if rel.parts[:1] == ("out",):
            continue
        for name in (*dirs, *files):
            path = Path(folder) / name
            if path.is_symlink():
                found[str(rel / name)] = ("link", os.readlink(path))
            elif path.is_file():
                found[str(rel / name)] = ("file", hashlib.sha1(path.read_bytes()).hexdigest())
            else:
                found[str(rel / name)] = ("dir",)
    return found


def run_reader(name: str, read: Callable[[], Any], refusals: list[str]) -> Any:
    """``read()``; a refusal must be one line of one of rlgrasp's errors, naming no secret."""
    try:
        return read()
    except REFUSALS as exc:
        message = str(exc.code if isinstance(exc, SystemExit) else exc)
        assert "\n" not in message.strip(), f"{name}: more than one line: {message}"
        assert SECRET not in message, f"{name}: printed an environment value: {message}"
        refusals.append(f"{name}: {message}")
        return None


# --- config payloads ---------------------------------------------------------------------------
FOREIGN = ["builtins.open", "shutil.copyfile", "os.remove", "pathlib.Path.touch", "os.makedirs", "io.open"]
WRONG_KIND = {  # rlgrasp's own classes, each at a node of another kind
    "env": [PARTS["logger"]["mlflow"], PARTS["collector"]["single"], PARTS["algo"]["ppo"]],
    "collector": [
        PARTS["logger"]["tensorboard"],
        PARTS["env"]["grasp"],
        "rlgrasp.train.checkpoint.save_checkpoint",
    ],
    "algo": [PARTS["logger"]["mlflow"], PARTS["algo_term"]["rnd"]],
    "algo.terms.imitation": [PARTS["logger"]["mlflow"], PARTS["algo"]["sac"]],
    "env.task": [PARTS["env"]["grasp"], PARTS["logger"]["wandb"]],
}
KINDS = [
    "call_node",
    "instantiate_key",
    "foreign_target",
    "wrong_kind",
    "interpolation",
    "dotted_key",
    "old_env",
    "old_collector",
    "logger_endpoint",
    "not_mapping",
    "spec",
    "nan_weight",
    "not_checkpoint",
]


def _node_paths(node: Any, path: tuple = ()) -> list[tuple]:
    """The path of every mapping in a config (where a payload can go)."""
    out = [path]
    if isinstance(node, dict):
        for key, value in node.items():
            if isinstance(value, dict):
                out += _node_paths(value, (*path, key))
    return out


def _at(config: dict, path: tuple) -> dict:
    for key in path:
        config = config[key]
    return config


def _call(box: Path, target: str) -> dict[str, Any]:
    victim, created = str(box / "victims" / "keep.txt"), str(box / "victims" / "created")
    return {
        "builtins.open": {"_target_": target, "_args_": [created, "w"]},
        "io.open": {"_target_": target, "file": created, "mode": "w"},
        "shutil.copyfile": {"_target_": target, "src": victim, "dst": created},
        "os.remove": {"_target_": target, "_args_": [victim]},
        "pathlib.Path.touch": {"_target_": target, "_args_": [created]},
        "os.makedirs": {"_target_": target, "name": created},
    }.get(target, {"_target_": target, "tracking_uri": f"file://{created}", "run_dir": created})


def apply_config_payload(state: dict, kind: str, data: st.DataObject, box: Path) -> Any:
    """``state`` (a copy) with one payload of ``kind`` at a place ``data`` draws; the object to save."""
    config = state["config"]
    where = data.draw(st.sampled_from(_node_paths(config)), label="where")
    node, target = _at(config, where), data.draw(st.sampled_from(FOREIGN), label="target")
    key = data.draw(st.sampled_from(["randomization", "x", "objects", "terms", "camera"]), label="key")
    if kind == "call_node":
        node[key] = _call(box, target) if data.draw(st.booleans()) else [_call(box, target)]
    elif kind == "instantiate_key":
        node[data.draw(st.sampled_from(["_args_", "_partial_", "_recursive_", "_convert_"]))] = [
            str(box / "x")
        ]
        node.setdefault("_target_", target)
    elif kind == "foreign_target":
        node.update(_call(box, target))
    elif kind == "wrong_kind":
        at = data.draw(st.sampled_from(sorted(WRONG_KIND)), label="node")
        parent = config
        for part in at.split(".")[:-1]:
            parent = parent.setdefault(part, {})
        leaf = at.split(".")[-1]
        parent[leaf] = {**(parent.get(leaf) or {}), **_call(box, data.draw(st.sampled_from(WRONG_KIND[at])))}
    elif kind == "interpolation":
        text = data.draw(
            st.sampled_from([f"${{oc.env:{SECRET_VAR}}}", "${oc.create:{a: 1}}", "x${env.robot}"])
        )
        node[key] = text
    elif kind == "dotted_key":
        config[data.draw(st.sampled_from(["algo.terms.x", "env.randomization", "a.b"]))] = _call(box, target)
    elif kind == "old_env":
        module = data.draw(
            st.sampled_from(
                [
                    "builtins:open",
                    "shutil:copyfile",
                    "os:makedirs",
                    "rlgrasp.train.checkpoint:save_checkpoint",
                ]
            )
        )
        config["env"] = {
            "gym_factory": module,
            "kwargs": {"file": str(box / "victims" / "created"), "mode": "w"},
        }
    elif kind == "old_collector":
        config["collector"] = {"backend": data.draw(st.sampled_from(FOREIGN + [PARTS["logger"]["mlflow"]]))}
    elif kind == "logger_endpoint":
        config["logger"] = {
            "_target_": PARTS["logger"]["mlflow"],
            "tracking_uri": data.draw(
                st.sampled_from([f"file://{box / 'victims' / 'mlruns'}", "http://203.0.113.1:5000"])
            ),
        }
    elif kind == "not_mapping":
        part = data.draw(st.sampled_from(["env", "collector", "algo", "config"]))
        value = data.draw(st.sampled_from(["grasp", 3, ["x"], None]))
        if part == "config":
            state["config"] = value
        else:
            config[part] = value
    elif kind == "spec":
        key = data.draw(st.sampled_from(["obs_dim", "action_dim", "action_low"]))
        state["spec"][key] = data.draw(st.sampled_from(["49", -1, 1.5, [float("nan")], None]))
    elif kind == "nan_weight":
        name = data.draw(
            st.sampled_from(sorted(k for k, v in state["actor"].items() if v.is_floating_point()))
        )
        weight = state["actor"][name].clone().flatten()
        weight[data.draw(st.integers(0, weight.numel() - 1))] = data.draw(
            st.sampled_from([math.nan, math.inf])
        )
        state["actor"][name] = weight.reshape(state["actor"][name].shape)
    elif kind == "not_checkpoint":
        return data.draw(
            st.sampled_from(
                [{"weights": torch.zeros(3)}, [1, 2], {"actor": {}, "config": "x"}, {"config": {}}]
            )
        )
    return state


def config_readers(path: Path, bases: Bases, box: Path) -> list[tuple[str, Callable[[], Any]]]:
    """Every reader of a checkpoint, each as it loads and builds what it reads."""
    cfg, out = bases.train_cfg, box / "out"

    def resume() -> None:
        resume_cfg = copy.deepcopy(bases.resume_cfg)
        resume_cfg.paths.output_dir, resume_cfg.resume = str(out / "resumed"), str(path)
        merged, _ = prepare_run(resume_cfg, {"resume"})
        assert merged.logger == resume_cfg.logger  # the user's, never the file's

    def evaluation() -> None:
        source = prepare("checkpoint", str(path), "best")
        output_paths("onnx", str(out / "p.onnx"), path)
        prepare_teacher(str(path), source)  # the same file as the teacher of its own evaluation

    def upgrade() -> None:
        script = _script("upgrade_checkpoint")
        save_checkpoint(out / "upgraded.pt", script.load(path, False))

    return [
        ("read_checkpoint", lambda: read_checkpoint(path)),
        ("eval/enjoy/adr_report: prepare", evaluation),
        ("export: load_source", lambda: load_source(str(path), "best")),
        ("resume", resume),
        ("algo.init_from", lambda: warm_start(torch.nn.Linear(1, 1), str(path), cfg.env, cfg.model)),
        ("teacher", lambda: load_teacher(str(path), {"privileged_dim": 1}, OmegaConf.to_container(cfg.env))),
        ("upgrade_checkpoint", upgrade),
    ]


_SCRIPTS: dict[str, Any] = {}


def _script(name: str) -> Any:
    if name not in _SCRIPTS:
        spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
        _SCRIPTS[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(_SCRIPTS[name])
    return _SCRIPTS[name]


def _check_config_case(bases: Bases, data: st.DataObject) -> None:
    base = data.draw(st.sampled_from(sorted(bases.checkpoints)), label="base")
    kind = data.draw(st.sampled_from(KINDS), label="payload")
    with sandbox() as box:
        state = apply_config_payload(copy.deepcopy(bases.checkpoints[base]), kind, data, box)
        path = box / "received" / "checkpoints" / "best.pt"
        path.parent.mkdir(parents=True)
        torch.save(state, path)
        shutil.copy(path, path.with_name("last.pt"))
        (box / "received" / ".hydra").mkdir()
        hydra_cfg = {"experiment_name": f"${{oc.env:{SECRET_VAR}}}", "seed": "${seed}"}
        (box / "received" / ".hydra" / "config.yaml").write_text(json.dumps(hydra_cfg))
        before, refusals = snapshot(box), []
        for name, read in config_readers(path, bases, box):
            run_reader(name, read, refusals)
        records = run_reader("report", lambda: load_runs([str(box / "received")]), refusals)
        assert SECRET not in repr(records)
        assert snapshot(box) == before, f"{kind} on {base}: a file outside out/ changed"
        if not refusals:  # accepted (a logger's node is only recorded): it can build rlgrasp's parts only
            assert _targets(read_checkpoint(path)["config"]) <= REGISTERED, f"{kind} on {base}"


REGISTERED = {cls for parts in PARTS.values() for cls in parts.values()}


def _targets(node: Any) -> set[str]:
    """Every ``_target_`` of a config, at any depth."""
    if isinstance(node, dict):
        own = {str(node["_target_"])} if "_target_" in node else set()
        return own.union(*(_targets(v) for v in node.values()))
    if isinstance(node, list):
        return set().union(*(_targets(v) for v in node))
    return set()


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
@settings(
    max_examples=QUICK, deadline=None, suppress_health_check=list(HealthCheck), database=None, phases=PHASES
)
@given(data=st.data())
def test_config_payloads_act_on_nothing(bases: Bases, data: st.DataObject) -> None:
    _check_config_case(bases, data)


@pytest.mark.full
@settings(
    max_examples=FULL, deadline=None, suppress_health_check=list(HealthCheck), database=None, phases=PHASES
)
@given(data=st.data())
def test_config_payloads_act_on_nothing_full(bases: Bases, data: st.DataObject) -> None:
    _check_config_case(bases, data)


# --- folder payloads ---------------------------------------------------------------------------
FOLDER_KINDS = [
    "memmap_link",
    "frames_link",
    "truncated_memmap",
    "oversize_shape",
    "nan_memmap",
    "wrong_dtype",
    "wrong_shape",
    "pickle_file",
    "replay_dir_link",
    "replay_file_link",
    "truncated_replay",
    "nan_replay",
    "checkpoint_link",
    "checkpoints_dir_link",
]


def apply_folder_payload(kind: str, data: st.DataObject, box: Path, bases: Bases) -> tuple[Path, Path, Path]:
    """Copies of the demonstrations, the SAC run and the run directory in ``box`` with one payload."""
    demos, replay_run, run = box / "received_demos", box / "out" / "sac_run", box / "received_run"
    shutil.copytree(bases.demos, demos)
    shutil.copytree(bases.replay, replay_run)  # the resumed run's own folder: its output
    shutil.copytree(bases.run / "checkpoints", run / "checkpoints")
    frames, victim = demos / "frames", box / "victims" / "keep.txt"
    meta = json.loads((frames / "meta.json").read_text())
    entry = data.draw(
        st.sampled_from(sorted(k for k in meta if k not in ("shape", "device", "_type"))), label="entry"
    )
    file = frames / f"{entry}.memmap"
    chunks = sorted((replay_run / "replay").glob("*.pt"))
    if kind == "memmap_link":
        shutil.copy(file, victim.with_name("target.memmap"))
        file.unlink()
        file.symlink_to(victim.with_name("target.memmap") if data.draw(st.booleans()) else victim)
    elif kind == "frames_link":
        shutil.move(frames, box / "victims" / "frames")
        frames.symlink_to(box / "victims" / "frames")
    elif kind == "truncated_memmap":
        raw = file.read_bytes()
        file.write_bytes(raw[: data.draw(st.integers(0, max(len(raw) - 1, 0)))])
    elif kind == "oversize_shape":
        meta[entry]["shape"] = [data.draw(st.sampled_from([10**9, 2**40, 51]))] + meta[entry]["shape"][1:]
    elif kind == "nan_memmap":
        floats = [k for k in meta if isinstance(meta[k], dict) and meta[k].get("dtype") == "torch.float32"]
        file = frames / f"{data.draw(st.sampled_from(sorted(floats)))}.memmap"
        raw = bytearray(file.read_bytes())
        at = 4 * data.draw(st.integers(0, len(raw) // 4 - 1))
        raw[at : at + 4] = (
            torch.tensor([data.draw(st.sampled_from([math.nan, math.inf, -math.inf]))]).numpy().tobytes()
        )
        file.write_bytes(bytes(raw))
    elif kind == "wrong_dtype":
        meta[entry]["dtype"] = data.draw(
            st.sampled_from(["torch.int32", "torch.float64", "torch.uint8", "builtins.object"])
        )
    elif kind == "wrong_shape":
        shape = meta[entry]["shape"]
        meta[entry]["shape"] = [shape[0] // 2, *([shape[1] * 2] if len(shape) > 1 else [2])]
    elif kind == "pickle_file":
        (frames / "other.pickle").write_bytes(b"\x80\x04N.")
    elif kind == "replay_dir_link":
        outside = box / "victims" / "replay"
        shutil.copytree(replay_run / "replay", outside)
        (outside / "000009_16.pt").write_bytes(chunks[0].read_bytes())  # "newer than the checkpoint"
        shutil.rmtree(replay_run / "replay")
        (replay_run / "replay").symlink_to(outside)
    elif kind == "replay_file_link":
        chunks[-1].unlink()
        chunks[-1].symlink_to(victim)
    elif kind == "truncated_replay":
        raw = chunks[0].read_bytes()
        chunks[0].write_bytes(raw[: data.draw(st.integers(0, len(raw) - 1))])
    elif kind == "nan_replay":
        saved = torch.load(chunks[1], weights_only=True)
        saved["data"]["observation"][0, 0] = math.nan
        torch.save(saved, chunks[1])
    elif kind == "checkpoint_link":
        outside = box / "victims" / "elsewhere" / "checkpoints"
        outside.mkdir(parents=True)
        shutil.move(run / "checkpoints" / "last.pt", outside / "last.pt")
        (run / "checkpoints" / "last.pt").symlink_to(outside / "last.pt")
    elif kind == "checkpoints_dir_link":
        shutil.move(run / "checkpoints", box / "victims" / "checkpoints")
        (run / "checkpoints").symlink_to(box / "victims" / "checkpoints")
    (frames / "meta.json").write_text(
        json.dumps(meta)
    ) if frames.is_dir() and not frames.is_symlink() else None
    return demos, replay_run, run


def _check_folder_case(bases: Bases, data: st.DataObject) -> None:
    kind = data.draw(st.sampled_from(FOLDER_KINDS), label="payload")
    with sandbox() as box:
        demos, replay_run, run = apply_folder_payload(kind, data, box, bases)
        before, refusals = snapshot(box), []

        def replay() -> None:  # what a resumed SAC run does with its replay folder (SAC.load_replay)
            files = ReplayFiles(replay_run)
            files.discard_after(3)
            for part in files.read():
                assert part["observation"].isfinite().all()

        readers = {  # the readers of the folder the payload is in
            "demos": [("demos", lambda: load_demos(demos, bases.layout))],
            "replay": [("replay", replay)],
            "checkpoint": [
                ("eval of a run", lambda: prepare("checkpoint", str(run), "last")),
                ("resume of a run", lambda: load_checkpoint(run)),
                ("report", lambda: load_runs([str(run)])),
            ],
        }
        folder = "replay" if "replay" in kind else "checkpoint" if "checkpoint" in kind else "demos"
        for name, read in readers[folder]:
            run_reader(name, read, refusals)
        assert snapshot(box) == before, f"{kind}: a file outside out/ changed"
        assert refusals, f"{kind} was accepted by every reader"


@settings(
    max_examples=FOLDER_QUICK,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    database=None,
    phases=PHASES,
)
@given(data=st.data())
def test_folder_payloads_act_on_nothing(bases: Bases, data: st.DataObject) -> None:
    _check_folder_case(bases, data)


@pytest.mark.full
@settings(
    max_examples=FOLDER_FULL,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    database=None,
    phases=PHASES,
)
@given(data=st.data())
def test_folder_payloads_act_on_nothing_full(bases: Bases, data: st.DataObject) -> None:
    _check_folder_case(bases, data)
