"""Checkpoint configs of an older shape: backends named by strings, and ``algo``'s keys in one bag.

A checkpoint stores the resolved training config it was trained with. Older ones name the backends
with strings (``collector.backend: process|ray|single``, ``logger.backend: tensorboard|none``,
``logger.tracker: wandb|mlflow``), as ``policies/*.pt`` do, and keep ``algo``'s keys flat
(``algo.lr``, where today's config has ``algo.optim.lr``: ``rlgrasp.config.ALGO_KEYS``).
``upgrade_config`` maps such a config to today's shape, here and nowhere else:
``rlgrasp.train.checkpoint.read_checkpoint`` applies it to every checkpoint it reads (resume,
evaluation, export), and ``scripts/upgrade_checkpoint.py`` writes the result back.
"""

from __future__ import annotations

import copy
from typing import Any

from rlgrasp.config import PPOTermsConfig, moved_algo_key

COLLECTORS = {
    "process": "rlgrasp.train.collectors.ProcessCollector",
    "ray": "rlgrasp.train.collectors.RayCollector",
    "single": "rlgrasp.train.collectors.SingleCollector",
}
LOGGERS = {
    "tensorboard": "rlgrasp.train.logger.TensorBoardLogger",
    "none": "rlgrasp.train.logger.ConsoleLogger",
    "wandb": "rlgrasp.train.trackers.WandbLogger",
    "mlflow": "rlgrasp.train.trackers.MlflowLogger",
}
#: The keys each tracker's logger takes besides ``console_interval_s`` (the old schema had both's).
TRACKER_KEYS = {
    "wandb": ("project", "tags", "run_name", "entity", "mode"),
    "mlflow": ("project", "tags", "run_name", "tracking_uri"),
}


def nest_algo(algo: dict[str, Any]) -> dict[str, Any]:
    """A flat ``algo`` node of before in today's shape (a copy; a nested one comes back unchanged).
    PPO's terms get the ``_target_`` a flat config could not name: a resume keeps the checkpoint's
    config and would otherwise have no class to build them with."""
    nested: dict[str, Any] = {}
    for key, value in algo.items():
        path = moved_algo_key(key, algo.get("name")) if not isinstance(value, dict) else None
        node = nested
        *parents, leaf = (path or key).split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    if algo.get("name") == "ppo":
        for name, term in nested.get("terms", {}).items():
            default = getattr(PPOTermsConfig(), name, None)
            if isinstance(term, dict) and default is not None:
                term.setdefault("_target_", default._target_)
    return nested


#: The env's keywords of before the task was a part, now the lift task's (``env.task``).
TASK_KEYS = {"reward": "reward", "reward_weights": "weights", "success_height": "success_height"}
LIFT_TASK = "rlgrasp.envs.tasks.LiftTask"


def nest_task(env: dict[str, Any]) -> dict[str, Any]:
    """An ``env`` node of before the task part (``reward``, ``reward_weights``, ``success_height``,
    ``terminate_on_success`` as the env's own keywords) with them under ``env.task`` (a copy; one of
    today's shape comes back unchanged)."""
    env = dict(env)
    if "task" in env or not any(k in env for k in (*TASK_KEYS, "terminate_on_success")):
        return env  # today's shape, or nothing to move (an env of the user's own, a default lift)
    task: dict[str, Any] = {"_target_": LIFT_TASK}
    for old, new in (*TASK_KEYS.items(), ("terminate_on_success", "terminate_on_success")):
        if old in env:
            value = env.pop(old)
            if value is not None:
                task[new] = value
    env["task"] = task
    return env


def upgrade_config(config: dict[str, Any]) -> dict[str, Any]:
    """``config`` with string-named backends turned into ``_target_`` nodes (a copy; a config of
    today's shape comes back unchanged)."""
    config = copy.deepcopy(config)
    collector = config.get("collector")
    if isinstance(collector, dict) and "backend" in collector:
        backend = collector.pop("backend")
        collector["_target_"] = COLLECTORS.get(backend, backend)
        if backend != "ray":
            collector.pop("ray", None)
        config["collector"] = {"_target_": collector.pop("_target_"), **collector}
    logger = config.get("logger")
    if isinstance(logger, dict) and "backend" in logger:
        tracker = logger.get("tracker")
        kind = tracker if tracker in TRACKER_KEYS else logger["backend"]
        keep = ("console_interval_s", *TRACKER_KEYS.get(kind, ()))
        kept = {k: logger[k] for k in keep if k in logger}
        config["logger"] = {"_target_": LOGGERS.get(kind, kind), **kept}
    if isinstance(config.get("algo"), dict):
        config["algo"] = nest_algo(config["algo"])
    if isinstance(config.get("env"), dict):
        config["env"] = nest_task(config["env"])
    return config
