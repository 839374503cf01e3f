"""Checkpoints of an older shape: ``algo``'s keys in one bag, an algorithm's state at the top level.

Older checkpoints keep ``algo``'s keys flat (``algo.lr``, where today's config has ``algo.optim.lr``:
``rlgrasp.config.ALGO_KEYS``), as ``policies/*.pt`` do. ``nest_algo`` maps such a node to today's
shape; ``rlgrasp.received.read_config`` applies it to every config read from a file (with the other
older formats: a ``gym_factory`` env, string-named backends), as data.
"""

from __future__ import annotations

from typing import Any

from rlgrasp.algos.registry import term_targets
from rlgrasp.config import ENV_KEYS, moved_algo_key


def nest_algo(algo: dict[str, Any]) -> dict[str, Any]:
    """A flat ``algo`` node of before in today's shape (a copy; a nested one comes back unchanged).
    Terms an algorithm builds by class (PPO's) get the ``_target_`` its schema gives them, which a flat
    config could not name: a resume keeps the checkpoint's config and would otherwise have no class
    to build them with."""
    nested: dict[str, Any] = {}
    for key, value in algo.items():
        path = moved_algo_key(key, algo.get("name")) if not isinstance(value, dict) else None
        _set_path(nested, path or key, value)
    targets = term_targets(algo.get("name"))
    for name, term in nested.get("terms", {}).items():
        if isinstance(term, dict) and name in targets:
            term.setdefault("_target_", targets[name])
    return nested


def _set_path(node: dict[str, Any], path: str, value: Any) -> None:
    """``value`` at the dotted ``path`` of ``node``, the nodes on the way made as needed."""
    *parents, leaf = path.split(".")
    for part in parents:
        node = node.setdefault(part, {})
    node[leaf] = value


def algorithm_state(state: dict[str, Any]) -> dict[str, Any] | None:
    """The algorithm's own state in a checkpoint, None in a policy file (nothing to continue).

    Today each algorithm's state sits under its ``algo.name`` (SAC's always did, under ``sac``).
    Checkpoints written before that kept PPO's and DAgger's at the top level beside the core's entries
    (``critic``, ``optimizer``, a term's weights): the top level is then that state, read by the same
    ``load_state_dict`` with the same keys. The one place that knows the older layout."""
    name = ((state.get("config") or {}).get("algo") or {}).get("name")
    if isinstance(state.get(name), dict):
        return state[name]
    return state if "optimizer" in state else None


#: The env's keywords of before the task was a part, now the lift task's (``env.task``).
TASK_KEYS = {"reward": "reward", "reward_weights": "weights", "success_height": "success_height"}
LIFT_TASK = "rlgrasp.envs.tasks.LiftTask"
GRASP_ENV = "rlgrasp.envs.PandaGraspEnv"


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


def nest_env(env: dict[str, Any]) -> dict[str, Any]:
    """An ``env`` node of before the env took parts (``control_mode``, ``ee_yaw``, ``time_step``, ...
    as its own keywords: ``rlgrasp.config.ENV_KEYS``) with them under ``env.control`` and ``env.sim``
    (a copy; one of today's shape comes back unchanged). A ``robot_urdf`` becomes
    ``env.robot: {name: <arm>, model: <file>}``. An env of another class (a user's own, a standin)
    keeps its keywords: they are its own."""
    target = str(env.get("_target_") or GRASP_ENV)
    if not (target.startswith("rlgrasp.") and target.endswith(("PandaGraspEnv", "GraspEnv"))):
        return dict(env)
    env = nest_task(env)
    if not any(key in env for key in ENV_KEYS):
        return env
    model = env.pop("robot_urdf", None)
    nested = {k: dict(v) if isinstance(v, dict) else v for k, v in env.items() if k not in ENV_KEYS}
    for key in [k for k in env if k in ENV_KEYS]:
        _set_path(nested, ENV_KEYS[key], env[key])
    if model is not None and isinstance(nested.get("robot", "panda"), str):
        nested["robot"] = {"name": nested.get("robot", "panda"), "model": model}
    return nested
