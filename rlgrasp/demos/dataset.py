"""The demonstration file: a TensorDict memory map of transitions plus ``demos.json`` (what made it).

A directory ``<out>/demos`` holds ``frames/`` (``TensorDict.memmap``: one tensor file per entry,
read back without unpickling anything) and ``demos.json``: the observation layout, control mode and
action size the transitions were recorded with, the env config, and the summary. A run whose env
observes or acts otherwise is refused in one line: the numbers would load and mean something else.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.config import ConfigError
from rlgrasp.envs.cameras import GROUND_MASK_KEY, CameraSpec
from rlgrasp.envs.env_settings import env_setting
from rlgrasp.envs.tasks import task_name
from rlgrasp.legacy import nest_task
from rlgrasp.models.cnn import IMAGE_KEYS
from rlgrasp.models.spec import PRIVILEGED_KEY
from rlgrasp.received import ReceivedError, check_tree, read_memmap

FORMAT = 1
META = "demos.json"
FRAMES = "frames"
#: The env settings that change what an observation or an action means: the name a demonstrations
#: folder records each under (``demos.json``) and its path in the env config.
LAYOUT_KEYS = {"control_mode": "control.mode", "ee_yaw": "control.ee_yaw", "robot": "robot"}


class DemoError(ConfigError):
    """A demonstration file that cannot be used; the message names the file and why."""


@dataclass
class Demos:
    """Transitions (``observation``, ``action``, ``reward``, ``done``, ``episode``) and their meta."""

    frames: TensorDict
    meta: dict[str, Any]

    @property
    def episodes(self) -> int:
        return int(self.meta["summary"]["kept"])

    def returns(self, gamma: float) -> torch.Tensor:
        """Discounted return-to-go of each transition within its episode (the value targets of
        pre-training)."""
        reward, done = self.frames["reward"].flatten(), self.frames["done"].flatten()
        out = torch.zeros_like(reward)
        running = 0.0
        for i in range(reward.numel() - 1, -1, -1):
            running = float(reward[i]) + (0.0 if bool(done[i]) else gamma * running)
            out[i] = running
        return out


def layout_of(env: Any, env_cfg: dict[str, Any]) -> dict[str, Any]:
    """What an observation and an action mean in ``env``: part slices, sizes, control keys, and a
    camera's images (``images``: key -> shape; none without a camera). A goal task's Dict is recorded
    entry by entry (``observation``: the flat vector without its goal, ``achieved_goal``,
    ``desired_goal``); ``obs_dim`` is its ``observation``'s."""
    space = env.observation_space
    camera = isinstance(space, gym.spaces.Dict) and "state" in space.spaces
    goal = isinstance(space, gym.spaces.Dict) and not camera
    vector = space["state"] if camera else space["observation"] if goal else space
    return {
        "obs_dim": int(vector.shape[-1]),
        "action_dim": int(env.action_space.shape[0]),
        "obs_slices": {k: [s.start, s.stop] for k, s in env.unwrapped.obs_slices.items()},
        "images": {k: list(space[k].shape) for k in IMAGE_KEYS if camera and k in space.spaces},
        "camera_view": camera_view(env_cfg.get("camera")),
        **{k: env_setting(env_cfg, path) for k, path in LAYOUT_KEYS.items()},
    }


def camera_view(camera_cfg: Any) -> dict[str, Any] | None:
    """Where a camera looks from and how wide it sees, its mount's defaults filled in (``None``
    without a camera): images of one size from another pose show the scene otherwise, which the
    image shapes alone would let through."""
    if not camera_cfg:
        return None
    spec = CameraSpec.from_config(dict(camera_cfg))
    pose = {k: v.tolist() for k, v in spec.pose().items()}  # lists: as JSON reads them back
    return {"mount": spec.mount, **pose, "fov": spec.fov, "near": spec.near, "far": spec.far}


def write_demos(out: Path, frames: TensorDict, meta: dict[str, Any]) -> Path:
    """Write ``<out>/demos`` (frames memory-mapped, ``demos.json``); returns that directory."""
    target = Path(out) / "demos"
    frames.memmap(target / FRAMES)
    (target / META).write_text(json.dumps({"format": FORMAT, **meta}, indent=1))
    return target


def _meta(path: Path) -> dict[str, Any]:
    """``demos.json`` of ``path`` (the ``demos`` directory or the ``out`` directory above it)."""
    for folder in (path, path / "demos"):
        if (folder / META).is_file():
            try:
                return {**json.loads((folder / META).read_text()), "dir": str(folder)}
            except json.JSONDecodeError as exc:
                raise DemoError(f"algo.demos={path}: unreadable {META} ({exc})") from None
    if not path.exists():
        raise DemoError(f"algo.demos={path}: no such file or directory")
    raise DemoError(
        f"algo.demos={path}: not a demonstration directory (no {META}; record one with rlgrasp-demos)"
    )


def _parts_difference(recorded: dict[str, Any], run: dict[str, Any]) -> str:
    """Which named parts of the state one layout has and the other lacks, or holds elsewhere: the
    slices themselves run to a hundred entries, too many to compare by eye in one line."""
    only_run = [name for name in run if name not in recorded]
    only_recorded = [name for name in recorded if name not in run]
    moved = [name for name in run if name in recorded and run[name] != recorded[name]]
    said = []
    if only_run:
        said.append(f"this run's state has {', '.join(only_run)}, the recording's not")
    if only_recorded:
        said.append(f"the recording's state has {', '.join(only_recorded)}, this run's not")
    if moved:
        said.append(f"{', '.join(moved)} at other places")
    return "; ".join(said)


def load_demos(path: str | Path, layout: dict[str, Any]) -> Demos:
    """The demonstrations at ``path``, refused (``DemoError``, one line) when missing, empty or
    recorded with another observation layout or control than ``layout`` (``layout_of``)."""
    path = Path(path).expanduser()
    meta = _meta(path)
    if meta.get("images", {}) != layout.get("images", {}):  # first: the sizes differ too
        raise DemoError(
            f"algo.demos={path}: recorded with the images {meta.get('images', {})}, this run's camera gives "
            f"{layout.get('images', {})} (record them with the run's cameras= and image size)"
        )
    # Files recorded before the view was written carry none: the image check above is all they allow.
    if meta.get("camera_view") is not None and meta["camera_view"] != layout.get("camera_view"):
        raise DemoError(
            f"algo.demos={path}: recorded with the camera view {meta['camera_view']}, this run's camera is "
            f"{layout.get('camera_view')} (record them with the run's cameras=)"
        )
    for key in (*LAYOUT_KEYS, "obs_dim", "action_dim"):
        if meta.get(key) != layout.get(key):
            raise DemoError(
                f"algo.demos={path}: recorded with {key}={meta.get(key)!r}, this run has {layout.get(key)!r}"
            )
    if meta.get("obs_slices") != layout.get("obs_slices"):
        difference = _parts_difference(meta.get("obs_slices") or {}, layout.get("obs_slices") or {})
        raise DemoError(
            f"algo.demos={path}: recorded with another state layout: {difference} (record them with "
            "this run's env settings)"
        )
    if not meta.get("summary", {}).get("kept"):
        raise DemoError(f"algo.demos={path}: holds no demonstrations (0 episodes kept)")
    try:  # a received folder: read where it lies, never through a link (rlgrasp.received)
        check_tree(meta["dir"], f"algo.demos={path}")
    except ReceivedError as exc:
        raise DemoError(str(exc)) from None
    frames = _frames(path, Path(meta["dir"]) / FRAMES, layout)
    if not bool(frames["success"].any()):  # learning imitates successes only
        raise DemoError(f"algo.demos={path}: none of its {meta['summary']['kept']} episodes succeeded")
    return Demos(frames, meta)


def _frames(path: Path, folder: Path, layout: dict[str, Any]) -> TensorDict:
    """The transitions of ``folder``, read as data (``rlgrasp.received.read_memmap``: no link followed,
    each file's size checked, nothing written, NaN refused), each entry in the dtype and width this run
    reads; a folder copied without them (only ``demos.json``), or cut short, is refused naming it."""
    source = f"algo.demos={path}"
    if not (folder / "meta.json").is_file():
        raise DemoError(
            f"{source}: {folder} is missing (its {META} came without the "
            "transitions; copy the whole demos folder, or record it again with rlgrasp-demos)"
        )
    try:
        frames = read_memmap(folder, source)
    except ReceivedError as exc:
        raise DemoError(str(exc)) from None
    widths = {"observation": layout.get("obs_dim"), "action": layout.get("action_dim")}
    widths["next_observation"] = widths["observation"]
    for key, dtype in ENTRY_DTYPES.items():
        if key not in frames.keys():
            if key in REQUIRED_ENTRIES:
                raise DemoError(f"{source}: {folder} has no {key} entry")
            continue
        tensor = frames[key]
        if tensor.dtype != dtype:
            raise DemoError(f"{source}: refused: {key} is {tensor.dtype}, this run reads {dtype}")
        want = (frames.batch_size[0], widths[key]) if widths.get(key) else (frames.batch_size[0],)
        if tuple(tensor.shape) != want:
            raise DemoError(
                f"{source}: refused: {key} has the shape {list(tensor.shape)}, this run reads {list(want)}"
            )
    return frames


#: The dtype of each entry a learner reads (others, a camera's images, are checked finite only).
ENTRY_DTYPES = {
    "observation": torch.float32,
    "next_observation": torch.float32,
    "action": torch.float32,
    "reward": torch.float32,
    "done": torch.bool,
    "terminated": torch.bool,
    "success": torch.bool,
    "episode": torch.int64,
}
REQUIRED_ENTRIES = ("observation", "action", "reward", "done", "success")


def summary(episodes: list[dict[str, Any]], kept: int) -> dict[str, Any]:
    """Success, lengths and objects of the recorded episodes (printed and saved with the file)."""
    n = len(episodes)
    lengths = [e["length"] for e in episodes]
    objects: dict[str, list[int]] = {}
    for e in episodes:
        wins = objects.setdefault(e["object"] or "-", [0, 0])
        wins[0] += int(e["success"])
        wins[1] += 1
    return {
        "episodes": n,
        "kept": kept,
        "success_rate": sum(e["success"] for e in episodes) / max(n, 1),
        "mean_length": sum(lengths) / max(n, 1),
        "min_length": min(lengths, default=0),
        "max_length": max(lengths, default=0),
        "frames": sum(e["length"] for e in episodes if e["kept"]),
        "objects": {k: {"success": w, "episodes": c} for k, (w, c) in sorted(objects.items())},
    }


def task_reward(env_cfg: Any) -> str:
    """``task=lift env.task.reward=dense``: which task paid which reward (an env config of before the
    task part counts as lift's)."""
    if OmegaConf.is_config(env_cfg):  # a run's own composed config
        env_cfg = OmegaConf.to_container(env_cfg)
    task = nest_task(dict(env_cfg or {})).get("task") or "lift"
    name = task_name(task)
    reward = task.get("reward") if isinstance(task, Mapping) else None
    reward = reward or ("dense" if name == "lift" else "sparse")
    reward = reward if isinstance(reward, str) else "custom terms"
    return f"task={name} env.task.reward={reward}"


def demo_transitions(demos: Demos, env_cfg: Any) -> TensorDict:
    """The demonstrations as an off-policy learner's transitions (``observation``, ``action``,
    ``next``: ``observation``, ``reward``, ``done``, ``terminated``). Their rewards are the recording
    env's, so a run with another reward is refused. A file recorded before next observations were
    kept gives each step the following one, and drops each episode's last step (its successor is
    the next episode's first)."""
    recorded, here = (task_reward(env) for env in (demos.meta.get("env", {}), env_cfg))
    if recorded != here:
        raise DemoError(
            f"algo.demos={demos.meta['dir']}: recorded with {recorded}, this run has {here} (the replay "
            "learns from the recorded rewards; record them with the run's task and reward)"
        )
    f = demos.frames
    if "next_observation" in f.keys():
        keep = torch.ones(f.numel(), dtype=torch.bool)
        next_obs, terminated = f["next_observation"], f["terminated"]
    else:
        keep = ~f["done"]
        next_obs = torch.roll(f["observation"], -1, 0)
        terminated = torch.zeros(f.numel(), dtype=torch.bool)
    n = int(keep.sum())
    nxt = {
        "observation": next_obs[keep],
        "reward": f["reward"][keep].reshape(n, 1),
        "done": f["done"][keep].reshape(n, 1) | terminated[keep].reshape(n, 1),
        "terminated": terminated[keep].reshape(n, 1),
    }
    now = {"observation": f["observation"][keep], "action": f["action"][keep]}
    for key in (*IMAGE_KEYS, GROUND_MASK_KEY, PRIVILEGED_KEY):  # a camera's entries, with their next_
        if key in f.keys():
            now[key], nxt[key] = f[key][keep], f[f"next_{key}"][keep]
    return TensorDict({**now, "next": nxt}, batch_size=[n])


def demos_for(path: str, make_env: Any, env_cfg: Any) -> Demos:
    """The demonstrations at ``path`` checked against the env ``make_env`` builds."""
    env = make_env()
    try:
        layout = layout_of(env, dict(env_cfg))
    finally:
        env.close()
    return load_demos(path, layout)
