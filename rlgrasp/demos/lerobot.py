"""Demonstrations as LeRobot datasets, the interchange format of the field's imitation learners.

``export_demos`` writes a demonstrations folder (``rlgrasp-demos``) as a LeRobot dataset (v3.0, images
as PNG, ``rlgrasp.demos.lerobot_format``); ``import_dataset`` reads one back into a demonstrations
folder that ``algo.demos=`` accepts. A frame's entries map one to one:

    observation         observation.state              action      action
    reward              next.reward                    done        next.done
    terminated          next.terminated                success     next.success (an episode's last frame)
    privileged          observation.environment_state  rgb         observation.images.rgb (an image)
    depth               observation.depth              ground_mask observation.ground_mask
    next_<entry>        next.<its key>                 episode     episode_index

``next.*`` keys are the step's successor: LeRobot's policies read no ``next.`` key as an input, and
rlgrasp's off-policy learners need them. A frame-stacked rgb (more than 3 channels) stays a uint8
array. The env the frames came from (its layout and config, ``demos.json``) travels in
``meta/rlgrasp.json``, which LeRobot ignores; a dataset without it (recorded elsewhere) is imported
against the env the command line composes, its widths and images checked against that env's.

    python scripts/demos_lerobot.py export demos/cube/demos datasets/cube
    python scripts/demos_lerobot.py import datasets/cube demos/cube_lerobot [robot=... task=...]

The guide: docs/sparse.md#lerobot-datasets.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict

from rlgrasp.demos.dataset import DemoError, _meta, load_demos, summary, task_reward, write_demos
from rlgrasp.demos.lerobot_format import LeRobotFormatError, read_dataset, write_dataset
from rlgrasp.received import ReceivedError, check_tree

log = logging.getLogger("rlgrasp.demos")
SIDECAR = "meta/rlgrasp.json"
SUCCESS = "next.success"
#: Each frame entry's LeRobot key; ``next_<entry>`` is ``next.<key>``.
KEYS = {
    "observation": "observation.state",
    "action": "action",
    "reward": "next.reward",
    "done": "next.done",
    "terminated": "next.terminated",
    "privileged": "observation.environment_state",
    "rgb": "observation.images.rgb",
    "depth": "observation.depth",
    "ground_mask": "observation.ground_mask",
}
#: The entries that are an observation (each with its ``next_``).
OBSERVED = ("observation", "privileged", "rgb", "depth", "ground_mask")
#: A camera env's entries (imported only into an env with a camera).
CAMERA = ("privileged", "rgb", "depth", "ground_mask")
BOOLS = ("done", "terminated")


class LeRobotError(DemoError):
    """A dataset or demonstrations folder that cannot be converted; the message is one line."""


# --- export ----------------------------------------------------------------------------------------


def export_demos(src: str | Path, dst: str | Path, fps: int | None = None, task: str | None = None) -> dict:
    """Write the demonstrations at ``src`` as the LeRobot dataset folder ``dst`` (new); returns its
    ``meta/info.json``. ``fps`` defaults to the recording env's control rate, ``task`` to its task's
    name. The folder appears whole or not at all."""
    src, dst = Path(src).expanduser(), Path(dst).expanduser()
    if not src.exists():
        raise LeRobotError(f"{src}: no such demonstrations folder (record one with rlgrasp-demos)")
    meta = _meta(src)
    demos = load_demos(src, meta)  # read as received data, checked against its own layout
    frames = demos.frames
    columns, features = _columns(frames, meta)
    fps = fps or control_rate(meta.get("env") or {})
    task = task or task_reward(meta.get("env") or {}).split()[0].removeprefix("task=")
    episode = frames["episode"].numpy()
    episode = np.unique(episode, return_inverse=True)[1].astype(np.int64)  # kept episodes from 0
    sidecar = {k: v for k, v in meta.items() if k not in ("dir", "format")}
    with _new_folder(dst, "the dataset") as tmp:
        write_dataset(tmp, columns, features, episode, fps, task, robot_type=meta.get("robot"))
        (tmp / SIDECAR).write_text(json.dumps(sidecar, indent=1))
    log.info("wrote %s: %d episodes, %d frames at %d fps", dst, episode.max() + 1, len(episode), fps)
    return json.loads((dst / "meta/info.json").read_text())


def control_rate(env_cfg: dict[str, Any]) -> int:
    """Steps per second of the env that recorded (``env.sim``: ``substeps`` x ``time_step`` seconds a
    step; the defaults, 20, where a config names neither), rounded: LeRobot's fps is an integer."""
    from rlgrasp.envs.scene import SimConfig

    sim = env_cfg.get("sim") or {}
    step = float(sim.get("time_step", SimConfig.time_step)) * int(sim.get("substeps", SimConfig.substeps))
    return max(1, round(1.0 / step))


def _columns(frames: TensorDict, meta: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The frame entries as LeRobot columns and features (``KEYS``)."""
    columns: dict[str, np.ndarray] = {}
    features: dict[str, Any] = {}
    for entry in sorted(frames.keys()):
        if entry in ("episode", "success"):
            continue
        base = entry.removeprefix("next_")
        if base not in KEYS:
            raise LeRobotError(
                f"{meta['dir']}: the entry {entry!r} has no LeRobot key (known: {', '.join(KEYS)})"
            )
        key = KEYS[base] if base == entry else "next." + KEYS[base]
        values = frames[entry].numpy()
        image = key == KEYS["rgb"] and values.shape[1:2] == (3,)
        if image:  # one rgb frame: LeRobot's camera image, height x width x channels
            values = values.transpose(0, 2, 3, 1)
        shape = list(values.shape[1:]) or [1]
        features[key] = {
            "dtype": "image" if image else str(values.dtype),
            "shape": shape,
            "names": ["height", "width", "channels"] if image else _names(entry, shape, meta),
        }
        columns[key] = np.ascontiguousarray(values)
    columns[SUCCESS] = (frames["success"] & frames["done"]).numpy()  # the step that ends a success
    features[SUCCESS] = {"dtype": "bool", "shape": [1], "names": None}
    return columns, features


def _names(entry: str, shape: list[int], meta: dict[str, Any]) -> list[str] | None:
    """The state's element names from its parts (``ee_pos_0``, ...): what LeRobot shows per element."""
    if entry.removeprefix("next_") != "observation":
        return None
    names = [f"state_{i}" for i in range(shape[0])]
    for part, (start, stop) in (meta.get("obs_slices") or {}).items():
        for i in range(start, min(stop, shape[0])):
            names[i] = f"{part}_{i - start}"
    return names


class _new_folder:
    """A folder written beside ``dst`` and renamed into place when complete; removed on any error.
    ``dst`` must not exist: nothing of a user's is replaced."""

    def __init__(self, dst: Path, what: str, inner: str | None = None) -> None:
        if dst.exists() or dst.is_symlink():
            raise LeRobotError(f"{dst} exists already (choose another folder for {what})")
        self.dst, self.tmp = dst, dst.parent / f".{dst.name}.partial-{os.getpid()}"
        self.inner = inner  # the folder inside the temporary one that becomes dst

    def __enter__(self) -> Path:
        self.dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(self.tmp, ignore_errors=True)
        self.tmp.mkdir()
        return self.tmp

    def __exit__(self, kind: Any, *_: Any) -> None:
        if kind is None:
            os.replace(self.tmp / self.inner if self.inner else self.tmp, self.dst)
        shutil.rmtree(self.tmp, ignore_errors=True)


# --- import ----------------------------------------------------------------------------------------


def import_dataset(src: str | Path, out: str | Path, meta: dict[str, Any] | None = None) -> Path:
    """Read the LeRobot dataset at ``src`` into the demonstrations folder ``<out>/demos``; returns it.
    The env's layout comes from the dataset's ``meta/rlgrasp.json``, or, for a dataset without one,
    from ``meta`` (``layout_of`` an env, with ``env``: its config). The dataset is only read."""
    src, out = Path(src).expanduser(), Path(out).expanduser()
    source = f"lerobot dataset {src}"
    if not src.is_dir():
        raise LeRobotError(f"{source}: no such folder")
    try:
        check_tree(src, source)
    except ReceivedError as exc:
        raise LeRobotError(str(exc)) from None
    recorded = _sidecar(src, source)
    if recorded is None and meta is None:
        raise LeRobotError(
            f"{source}: has no {SIDECAR} (not written by rlgrasp): give the env it was recorded in "
            "(robot=, task=, cameras=, env.control.mode=) on the import command line"
        )
    meta = dict(recorded if recorded is not None else meta)  # type: ignore[arg-type]
    keys = [*KEYS.values(), *("next." + KEYS[e] for e in OBSERVED), SUCCESS]
    try:
        info, columns = read_dataset(src, source, keys)
    except LeRobotFormatError as exc:
        raise LeRobotError(str(exc)) from None
    images = {k for k, ft in info["features"].items() if k in columns and ft["dtype"] == "image"}
    frames, episodes = _frames(columns, meta, source, images)
    for key in ("dir", "format"):
        meta.pop(key, None)
    meta["summary"] = summary(episodes, len(episodes))
    meta.setdefault("policy", f"lerobot dataset {src.name}")
    target = out / "demos"
    with _new_folder(target, "the demonstrations (choose another out)", inner="demos") as tmp:
        write_demos(tmp, frames, meta)
        load_demos(tmp / "demos", meta)  # what algo.demos= reads: refused here, not in a run
    log.info(
        "wrote %s from %d frames at %s fps (train with algo.demos=%s)",
        target,
        len(frames),
        info["fps"],
        target,
    )
    return target


def _sidecar(src: Path, source: str) -> dict[str, Any] | None:
    path = src / SIDECAR
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise LeRobotError(f"{source}: unreadable {SIDECAR} ({type(exc).__name__})") from None
    if not isinstance(data, dict) or not isinstance(data.get("obs_dim"), int):
        raise LeRobotError(f"{source}: refused: {SIDECAR} is not an rlgrasp demonstrations' layout")
    return data


def _frames(
    columns: dict[str, np.ndarray], meta: dict[str, Any], source: str, images: set[str]
) -> tuple[TensorDict, list]:
    """The dataset's columns as rlgrasp's transitions, each entry's width checked against ``meta``;
    a camera's entries only into an env with a camera (``meta["images"]``)."""
    for needed in ("observation", "action", "reward"):
        if KEYS[needed] not in columns:
            raise LeRobotError(f"{source}: refused: no {KEYS[needed]!r} feature (needed: the {needed})")
    episode, ends = _episodes(columns, source)
    n = len(episode)
    entries: dict[str, np.ndarray] = {}
    camera = bool(meta.get("images"))
    for entry, key in KEYS.items():
        if entry in CAMERA and not camera:
            continue
        if key in columns:
            entries[entry] = _entry(entry, columns[key], key in images, source)
        if entry in OBSERVED and "next." + key in columns:
            entries["next_" + entry] = _entry(entry, columns["next." + key], False, source)
    _check_widths(entries, meta, source)
    entries["reward"] = entries["reward"].reshape(n).astype(np.float32)
    entries["done"] = entries.get("done", np.zeros(n, bool)).reshape(n) | ends
    succeeded = columns[SUCCESS].reshape(n).astype(bool) if SUCCESS in columns else np.ones(n, bool)
    success = np.zeros(n, bool)
    for e in np.unique(episode):
        success[episode == e] = succeeded[episode == e].any()
    _successors(entries, episode, ends)
    entries["success"], entries["episode"] = success, episode
    tensors = {
        k: torch.from_numpy(np.array(v)) for k, v in entries.items()
    }  # copies: pyarrow's are read-only
    frames = TensorDict(tensors, [n])
    episodes = [
        {
            "length": int((episode == e).sum()),
            "success": bool(success[episode == e][0]),
            "object": "",
            "kept": True,
        }
        for e in range(int(episode.max()) + 1 if n else 0)
    ]
    return frames, episodes


def _episodes(columns: dict[str, np.ndarray], source: str) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's episode, numbered from 0 in the dataset's order, and which frames end one. An
    episode's frames are contiguous and in order (``frame_index`` 0, 1, ...): anything else refused."""
    raw = columns["episode_index"].reshape(-1)
    frame = columns["frame_index"].reshape(-1)
    n = len(raw)
    start = np.r_[True, raw[1:] != raw[:-1]] if n else np.zeros(0, bool)
    episode = np.cumsum(start) - 1
    if len(np.unique(raw)) != int(start.sum()):
        raise LeRobotError(f"{source}: refused: episode_index: an episode's frames are not contiguous")
    first = np.flatnonzero(start)
    expected = np.arange(n) - np.repeat(first, np.diff(np.r_[first, n]))
    if (frame != expected).any():
        row = int(np.flatnonzero(frame != expected)[0])
        raise LeRobotError(
            f"{source}: refused: frame_index={int(frame[row])} at row {row}, expected {int(expected[row])} "
            "(an episode's frames in order from 0)"
        )
    ends = np.r_[start[1:], True] if n else np.zeros(0, bool)
    return episode.astype(np.int64), ends


def _entry(entry: str, values: np.ndarray, image: bool, source: str) -> np.ndarray:
    """One entry in the dtype and layout rlgrasp reads: floats as float32, images channels first."""
    if image:  # a LeRobot image: height x width x channels
        values = values.transpose(0, 3, 1, 2)
    if entry in BOOLS:
        if values.dtype != np.bool_:
            raise LeRobotError(f"{source}: refused: {KEYS[entry]} is {values.dtype}, read: bool")
        return values.reshape(len(values))
    if entry in ("rgb", "ground_mask"):
        return values
    if not np.issubdtype(values.dtype, np.floating):
        raise LeRobotError(f"{source}: refused: {KEYS[entry]} is {values.dtype}, read: float32 or float64")
    values = values.astype(np.float32)
    if not np.isfinite(values).all():
        raise LeRobotError(f"{source}: refused: {KEYS[entry]} holds NaN or infinite values")
    return values


def _check_widths(entries: dict[str, np.ndarray], meta: dict[str, Any], source: str) -> None:
    """The state's and action's widths, and the images, those of the env the frames are read into."""
    want = {"observation": [meta.get("obs_dim")], "action": [meta.get("action_dim")]}
    want.update({k: list(v) for k, v in (meta.get("images") or {}).items()})
    for entry, shape in want.items():
        have = list(entries[entry].shape[1:]) if entry in entries else None
        if have != shape:
            raise LeRobotError(
                f"{source}: refused: {KEYS[entry]} has the shape {have}, the env it is read into "
                f"gives {shape} (import it with the env it was recorded in)"
            )


def _successors(entries: dict[str, np.ndarray], episode: np.ndarray, ends: np.ndarray) -> None:
    """``next_<entry>`` where the dataset has none: the episode's next frame (its last repeats). With
    a successor so made, or no ``next.terminated``, next observations are dropped altogether: rlgrasp
    then learns from each step's following frame and leaves out each episode's last step, whose
    successor the dataset does not hold."""
    made = False
    for entry in OBSERVED:
        if entry in entries and "next_" + entry not in entries:
            following = np.concatenate([entries[entry][1:], entries[entry][-1:]])
            following[ends] = entries[entry][ends]
            entries["next_" + entry] = following
            made = True
    if made or "terminated" not in entries or "next_observation" not in entries:
        entries.pop("next_observation", None)
        entries.pop("terminated", None)


# --- command line ----------------------------------------------------------------------------------


def _import_meta(overrides: list[str]) -> dict[str, Any]:
    """The layout and config of the env ``overrides`` compose (as ``rlgrasp-demos``'s)."""
    from omegaconf import OmegaConf

    from rlgrasp.compose import compose_config
    from rlgrasp.demos.dataset import layout_of
    from rlgrasp.envs.factory import env_factory

    cfg = compose_config("demos", ["out=.", *overrides])
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    env = env_factory(env_cfg)()
    try:
        return {**layout_of(env, env_cfg), "env": env_cfg}
    finally:
        env.close()


def main(argv: list[str] | None = None) -> None:
    """``export SRC DST`` or ``import SRC OUT [env overrides]``; a refusal is one line and exit 2."""
    from rlgrasp.overrides import OneLineParser

    parser = OneLineParser(prog="demos_lerobot.py", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    exp = sub.add_parser("export", help="a demonstrations folder to a new LeRobot dataset folder")
    exp.add_argument("src", help="a demonstrations folder (rlgrasp-demos out=...)")
    exp.add_argument("dst", help="the LeRobot dataset folder to write (new)")
    exp.add_argument(
        "--fps", type=int, default=None, help="frames per second (default: the env's control rate)"
    )
    exp.add_argument("--task", default=None, help="the task string (default: the task's name)")
    imp = sub.add_parser("import", help="a LeRobot dataset folder to <out>/demos")
    imp.add_argument("src", help="a LeRobot dataset folder (v3.0, images not videos)")
    imp.add_argument("out", help="the folder to write demos/ into (new), as rlgrasp-demos out=")
    imp.add_argument("overrides", nargs="*", help="the env, for a dataset not written by rlgrasp")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="[%(levelname)s] %(message)s")
    try:
        if args.command == "export":
            export_demos(args.src, args.dst, args.fps, args.task)
        else:
            if not Path(args.src).is_dir():
                raise LeRobotError(f"lerobot dataset {args.src}: no such folder")
            recorded = (Path(args.src) / SIDECAR).is_file()
            if recorded and args.overrides:
                raise LeRobotError(
                    f"{args.src}: records its env ({SIDECAR}); env overrides are for other datasets"
                )
            import_dataset(args.src, args.out, None if recorded else _import_meta(args.overrides))
    except (DemoError, LeRobotFormatError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
