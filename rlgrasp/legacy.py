"""Configs and checkpoints of an older shape, mapped to today's, as data.

Older checkpoints keep ``algo``'s keys flat (``algo.lr``, where today's config has ``algo.optim.lr``:
``ALGO_KEYS``) and the env's keywords flat (``env.control_mode``: ``ENV_KEYS``), as ``policies/*.pt``
do; before the task was a part its reward keys were the env's; PPO's and DAgger's state sat at the top
level of a checkpoint. ``rlgrasp.received.read_config`` applies ``nest_config`` to every config read
from a file, and an old override on the command line is told its new key (``rlgrasp.overrides``).
Modules that moved (``MOVED_MODULES``) are named by their old path in the ``_target_`` of a part in
older files; ``moved_target`` gives today's path, which ``read_config`` reads back into a short name.

The one place that knows the older layouts. It sits at the bottom of the package beside
``rlgrasp.received`` (strings and the algorithms' registry, no torch), so that reading a received
file never imports the training core.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from rlgrasp.algos.registry import entry

#: Modules that moved, by their dotted path of before -> today's. A checkpoint or a run folder written
#: before names its parts by the old path (its ``collector._target_`` is
#: ``rlgrasp.train.collectors.ProcessCollector``); ``rlgrasp.received`` reads each ``_target_`` through
#: ``moved_target`` first. No module is left at an old path: this map is how an old name still loads.
MOVED_MODULES = {
    # rlgrasp.train split by role: the way to the learner's batches, ...
    "rlgrasp.train.collect": "rlgrasp.train.collection.collect",
    "rlgrasp.train.collectors": "rlgrasp.train.collection.collectors",
    "rlgrasp.train.batches": "rlgrasp.train.collection.batches",
    "rlgrasp.train.adr_sync": "rlgrasp.train.collection.adr_sync",
    # ... the evaluations beside the loop, ...
    "rlgrasp.train.evaluate": "rlgrasp.train.evaluation.evaluate",
    "rlgrasp.train.evaluations": "rlgrasp.train.evaluation.evaluations",
    "rlgrasp.train.eval_process": "rlgrasp.train.evaluation.eval_process",
    # ... where the curves go, ...
    "rlgrasp.train.logger": "rlgrasp.train.tracking.logger",
    "rlgrasp.train.trackers": "rlgrasp.train.tracking.trackers",
    "rlgrasp.train.metrics": "rlgrasp.train.tracking.metrics",
    # ... and PPO's curiosity term, beside PPO.
    "rlgrasp.train.rnd": "rlgrasp.algos.ppo.rnd",
}


def moved_target(target: str) -> str:
    """Today's dotted path of a ``module.Class`` path of before (``rlgrasp.train.rnd.RND`` ->
    ``rlgrasp.algos.ppo.rnd.RND``); any other string comes back unchanged."""
    module, dot, name = target.rpartition(".")
    new = MOVED_MODULES.get(module)
    return f"{new}.{name}" if dot and new else target


#: Where each flat ``algo`` key of before lives now (``algo.<key>`` -> ``algo.<path>``), for every
#: algorithm of then; a key moves only where the algorithm's schema has the path (``teacher`` is PPO's
#: ``terms.teacher.checkpoint``; DAgger's own ``algo.teacher`` did not move).
ALGO_KEYS = {
    **{k: f"loss.{k}" for k in ("gamma", "gae_lambda", "gae_every_epoch", "clip_epsilon", "entropy_coeff")},
    **{k: f"loss.{k}" for k in ("critic_coeff", "loss_critic_type", "normalize_advantage")},
    **{k: f"loss.{k}" for k in ("tau", "num_critics", "alpha_init", "target_entropy")},
    **{k: f"optim.{k}" for k in ("lr", "adam_eps", "max_grad_norm", "epochs", "minibatch_size", "ema_decay")},
    **{
        k: f"optim.{k}"
        for k in ("actor_lr", "critic_lr", "alpha_lr", "batch_size", "utd_ratio", "actor_every")
    },
    **{
        k: f"schedule.{k}"
        for k in ("anneal_lr", "min_lr_frac", "anneal_lr_frames", "target_kl", "desired_kl")
    },
    **{k: f"schedule.{k}" for k in ("critic_warmup_frames", "beta0", "beta_decay")},
    **{k: f"replay.{k}" for k in ("buffer_frames", "learning_starts", "demo_ratio")},
    "save_replay": "replay.save",
    **{f"critic_{k}": f"critic.{k}" for k in ("hidden_sizes", "activation", "layer_norm", "privileged")},
    **{f"bc_{k}": f"pretrain.{k}" for k in ("epochs", "lr", "minibatch_size", "only")},
    **{f"demo_{k}": f"terms.imitation.{k}" for k in ("coeff", "decay", "minibatch_size")},
    "bc_coeff": "terms.imitation.coeff",
    "teacher": "terms.teacher.checkpoint",
    **{f"teacher_{k}": f"terms.teacher.{k}" for k in ("coeff", "decay")},
    **{f"rnd_{k}": f"terms.rnd.{k}" for k in ("coeff", "gamma", "features", "update_fraction")},
    **{f"aux_{k}": f"terms.aux.{k}" for k in ("coeff", "parts")},
    "augment": "augment.kind",
    **{f"augment_{k}": f"augment.{k}" for k in ("grey", "shift")},
    "image_shift": "augment.shift",
}


#: Where each flat ``env`` keyword of before the env took parts lives now (``env.<key>`` ->
#: ``env.<path>``): old checkpoints load (``rlgrasp.legacy.nest_env``) and an old override
#: names its new key. ``robot_urdf`` became ``env.robot: {name: <arm>, model: <file>}``.
ENV_KEYS = {
    "control_mode": "control.mode",
    **{k: f"control.{k}" for k in ("ee_step", "ee_yaw", "yaw_step", "joint_step", "torque_fraction")},
    "gravity_compensation": "control.gravity_compensation",
    **{k: f"sim.{k}" for k in ("time_step", "substeps", "solver_iterations", "max_episode_steps")},
    **{k: f"sim.{k}" for k in ("collision_model", "visual")},
    "render_width": "sim.viewer.width",
    "render_height": "sim.viewer.height",
    **{f"camera_{k}": f"sim.viewer.{k}" for k in ("distance", "yaw", "pitch")},
    "robot_urdf": "robot.model",
}


def moved_algo_key(key: str, algo_name: str | None = None) -> str | None:
    """Today's path of a flat ``algo`` key of before (``lr`` -> ``optim.lr``); None for a key that
    did not move (``demos``, ``init_from``, DAgger's ``teacher``: the algorithm ``algo_name``'s schema
    has no such path) or never existed."""
    path = ALGO_KEYS.get(key)
    found = entry(algo_name)
    if path is None or found is None:
        return path
    return path if has_key(found.schema_class(), path) else None


def has_key(schema: type, path: str) -> bool:
    """Whether the dataclass ``schema`` has the dotted key ``path`` (``optim.lr``)."""
    node: Any = schema
    for part in path.split("."):
        fields = {f.name: f for f in dataclasses.fields(node)} if dataclasses.is_dataclass(node) else {}
        if part not in fields:
            return False
        field = fields[part]
        if field.default_factory is not dataclasses.MISSING:
            node = type(field.default_factory())
        else:
            node = field.type if isinstance(field.type, type) else None
    return True


def term_targets(name: Any) -> Mapping[str, str]:
    """The default ``_target_`` of each of an algorithm's ``algo.terms`` that is built by class (PPO's),
    for a config written before the terms named one."""
    found = entry(name)
    if found is None:
        return {}
    schema = found.schema_class()
    terms = next((f for f in dataclasses.fields(schema) if f.name == "terms"), None)
    if terms is None or terms.default_factory is dataclasses.MISSING:
        return {}
    default = terms.default_factory()
    return {
        f.name: getattr(default, f.name)._target_
        for f in dataclasses.fields(default)
        if hasattr(getattr(default, f.name), "_target_")
    }


def nest_config(config: dict[str, Any]) -> dict[str, Any]:
    """A config read from a file with its ``env`` and ``algo`` nodes in today's shape (``nest_env``,
    ``nest_algo``; each a copy, one of today's shape unchanged). Data only: the classes it writes are
    rlgrasp's lift task and the terms' of the algorithm the config names, from the registry."""
    config = dict(config)
    if isinstance(config.get("env"), dict):
        config["env"] = nest_env(config["env"])
    if isinstance(config.get("algo"), dict):
        config["algo"] = nest_algo(config["algo"])
    return config


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
    as its own keywords: ``rlgrasp.legacy.ENV_KEYS``) with them under ``env.control`` and ``env.sim``
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
