"""Write a policy folder: ``model.safetensors``, ``config.json`` and a model card, read without unpickling.

The format and its reader: ``rlgrasp.policy_file``. Written by ``rlgrasp-export
format=folder`` (``rlgrasp.export``, which checks the folder's actions against the checkpoint's)
and ``scripts/policy_folder.py`` (a ``.pt`` policy -> a folder).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
import yaml

from rlgrasp.envs.env_settings import env_setting
from rlgrasp.envs.robot import robot_label
from rlgrasp.policy_file import (
    CARD,
    CONFIG,
    RECORDS,
    WEIGHTS,
    package_versions,
    safetensors_torch,
)
from rlgrasp.received import FOLDER_FORMAT, FORMAT_VERSION
from rlgrasp.utils import dumps

#: What ``config.json``'s ``interface`` keeps of ``rlgrasp.export.describe`` (the env's keywords are
#: in ``config.env``; the source checkpoint is recorded apart, without its local path).
INTERFACE_KEYS = (
    "inputs",
    "output",
    "observation_layout",
    "camera",
    "images",
    "action_meaning",
    "action_low",
    "action_high",
    "control_mode",
    "control_hz",
    "deterministic",
    "env_id",
)


def plain(value: Any) -> Any:
    """``value`` as JSON data: tensors as lists, tuples as lists, a non-finite float as ``None``
    (JSON has no NaN; a run that never evaluated records ``-inf``)."""
    if isinstance(value, torch.Tensor):
        return plain(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def folder_config(ckpt: Mapping[str, Any], interface: Mapping[str, Any], source: Path) -> dict[str, Any]:
    """``config.json``: what rebuilds the policy and its env (the run's ``env`` and ``model`` in
    today's shape, ``algo.name``), the spec, the run's records, and what the vectors mean."""
    config = ckpt["config"]
    algo = config.get("algo") or {}
    kept_algo = {k: algo[k] for k in ("name", "teacher") if k in algo}  # teacher: a camera student's
    randomization = (config.get("eval") or {}).get("randomization")
    run = {
        "env": config["env"],
        "model": config["model"],
        "algo": kept_algo,
        **({"eval": {"randomization": randomization}} if randomization is not None else {}),
        **{k: config[k] for k in ("experiment_name", "seed") if k in config},
    }
    return plain(
        {
            "format": FOLDER_FORMAT,
            "format_version": FORMAT_VERSION,
            "kind": ckpt.get("kind", "state"),
            "config": run,
            "spec": ckpt["spec"],
            **{k: ckpt[k] for k in RECORDS if k in ckpt},
            "interface": {
                **{k: interface[k] for k in INTERFACE_KEYS if k in interface},
                "normalization": normalization(config["model"]),
            },
            "source": {"file": source.name, "sha256": interface.get("checkpoint", {}).get("sha256")},
            "written_by": package_versions(("torch", "safetensors", "rlgrasp"), missing=None),
        }
    )


def normalization(model: Mapping[str, Any]) -> str:
    """What a reader without rlgrasp applies to a raw observation before the first layer
    (``rlgrasp.models.mlp.RunningNorm``, eps 1e-8)."""
    if not model.get("obs_norm", True):
        return "none: the raw observation goes into the first layer"
    clip = model.get("obs_clip", 10.0)
    return (
        "(observation - norm.mean) / sqrt(norm.var + 1e-8), clipped to "
        f"+-{clip} (the tensors *.norm.mean and *.norm.var of {WEIGHTS})"
    )


def write_policy_folder(
    ckpt: Mapping[str, Any], folder: str | Path, interface: Mapping[str, Any], source: Path, name: str
) -> Path:
    """Write ``folder`` (created; its three files replaced): the actor's tensors, ``config.json``
    and the model card of the policy ``name``. ``interface``: ``rlgrasp.export.describe`` of the
    checkpoint and its env; ``source``: the checkpoint it came from (its name is recorded)."""
    st = safetensors_torch()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = folder_config(ckpt, interface, source)
    # contiguous, unshared copies: safetensors refuses views and tensors sharing memory
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in ckpt["actor"].items()}
    (folder / WEIGHTS).write_bytes(st.save(tensors, metadata={"format": FOLDER_FORMAT, "config": CONFIG}))
    (folder / CONFIG).write_text(dumps(meta), encoding="utf-8")
    (folder / CARD).write_text(model_card(meta, name), encoding="utf-8")
    return folder


def evaluation(meta: Mapping[str, Any]) -> dict[str, float] | None:
    """The run's recorded evaluation (``last_eval``, else ``best_eval_success``), ``None`` without one."""
    last = meta.get("last_eval") or {}
    found = {k: last[k] for k in ("success_rate", "mean_reward") if isinstance(last.get(k), (int, float))}
    best = meta.get("best_eval_success")
    if "success_rate" not in found and isinstance(best, (int, float)):
        found["success_rate"] = best
    return {k: round(float(v), 4) for k, v in found.items()} or None


def card_metadata(meta: Mapping[str, Any], name: str) -> dict[str, Any]:
    """The model card's YAML block, as the Hugging Face Hub reads it (``library_name``, ``tags``,
    ``model-index`` with the run's own evaluation when it recorded one)."""
    env = meta["config"]["env"]
    algo = meta["config"]["algo"].get("name", "unknown")
    robot = robot_label(env.get("robot"))  # a name, or a user's arm as {name, model}
    task, objects = _task_name(env), str(env.get("objects", "cube"))
    tags = ["reinforcement-learning", "robotics", "pybullet", "grasping", "rlgrasp", algo, robot, task]
    if meta["kind"] == "vision":
        tags.append("vision")
    card: dict[str, Any] = {
        "library_name": "rlgrasp",
        "license": "mit",
        "pipeline_tag": "reinforcement-learning",
        "tags": list(dict.fromkeys(tags)),
    }
    results = evaluation(meta)
    if results:
        env_id = meta["interface"].get("env_id", "rlgrasp/PandaGrasp-v0")
        names = {"success_rate": "success rate", "mean_reward": "mean episode return"}
        card["model-index"] = [
            {
                "name": name,
                "results": [
                    {
                        "task": {"type": "reinforcement-learning", "name": "reinforcement-learning"},
                        "dataset": {"type": env_id, "name": f"{env_id} ({task} {objects}, {robot})"},
                        "metrics": [
                            {"type": k, "value": v, "name": names[k], "verified": False}
                            for k, v in results.items()
                        ],
                    }
                ],
            }
        ]
    return card


def _task_name(env: Mapping[str, Any]) -> str:
    """``lift`` for ``rlgrasp.envs.tasks.LiftTask`` (the env's task node, lift when it has none)."""
    target = str((env.get("task") or {}).get("_target_", "LiftTask")).rsplit(".", 1)[-1]
    words = "".join(f"_{c.lower()}" if c.isupper() else c for c in target.removesuffix("Task"))
    return words.lstrip("_") or "lift"


def model_card(meta: Mapping[str, Any], name: str) -> str:
    """``README.md``: the YAML block, what the policy does, how to evaluate it and how to read it."""
    head = yaml.safe_dump(card_metadata(meta, name), sort_keys=False, default_flow_style=False)
    env, spec = meta["config"]["env"], meta["spec"]
    algo = meta["config"]["algo"].get("name", "unknown")
    results = evaluation(meta)
    shown = ", ".join(f"{k} {v}" for k, v in results.items()) if results else "none recorded"
    versions = ", ".join(f"{k} {v}" for k, v in (meta.get("versions") or {}).items())
    images = " and its camera images" if meta["kind"] == "vision" else ""
    return f"""---
{head}---

# {name}

An rlgrasp policy trained with `{algo}`: the
`{robot_label(env.get("robot"))}` arm, task `{_task_name(env)}`, objects `{env.get("objects", "cube")}`,
randomization `{env.get("randomization")}`, `{env_setting(env, "control.mode")}` control at
{meta["interface"].get("control_hz")} Hz. It maps a {spec["obs_dim"]}-value observation{images} to
{spec["action_dim"]} actions in [-1, 1]; `{CONFIG}`'s `interface` says what each entry means.

| file | holds |
|---|---|
| `{WEIGHTS}` | the actor's weights and the observation normalizer's statistics (plain tensors) |
| `{CONFIG}` | the run's env and model config, the spec (sizes, action bounds), what each entry means |
| `{CARD}` | this card |

Nothing in the folder is unpickled: reading it is `safetensors` and `json`.

## Evaluate it

```bash
pip install -e ".[policy]"                    # in an rlgrasp checkout: safetensors
rlgrasp-eval ckpt=<this folder> episodes=100  # seeds 0-99, success with a 95% interval
```

The run's own evaluation: {shown} (`model-index` above; after {meta.get("frames")} frames).

## Read it without rlgrasp

```python
import json
from safetensors.numpy import load_file

weights = load_file("{WEIGHTS}")  # name -> numpy array
config = json.load(open("{CONFIG}"))
print(config["interface"]["normalization"], config["interface"]["action_meaning"])
```

## Provenance

Converted from `{meta["source"]["file"]}` (sha256 `{meta["source"]["sha256"]}`); experiment
`{meta["config"].get("experiment_name")}`, seed {meta["config"].get("seed")}. Trained with {versions}.
"""
