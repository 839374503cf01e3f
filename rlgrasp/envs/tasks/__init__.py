"""Tasks: what an episode asks of the arm, its success and its reward terms.

``lift`` (grasp and lift, the default), and the goal tasks ``pick_place``, ``push`` and ``stack``
(``rlgrasp.envs.tasks.goal``). The env is given its task as ``env.task``: a name of ``TASKS``, or a
node whose ``_target_`` is a task class (rlgrasp's or the user's own: ``docs/tasks.md``) with its
keywords.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rlgrasp.envs.tasks.base import NOMINAL_OBJECT_XY, Task
from rlgrasp.envs.tasks.goal import GoalTask, PickPlaceTask, PushTask, StackTask, goal_distance
from rlgrasp.envs.tasks.lift import LiftTask
from rlgrasp.envs.tasks.terms import RewardConfigError, RewardTerms, import_object

#: The tasks a config (or a received checkpoint) may name by their short name.
TASKS: dict[str, type[Task]] = {
    "lift": LiftTask,
    "pick_place": PickPlaceTask,
    "push": PushTask,
    "stack": StackTask,
}


def task_class(spec: Any) -> type[Task]:
    """The class ``env.task`` names: a short name, ``{name: ...}`` or ``{_target_: ...}``."""
    if isinstance(spec, str):
        name = spec
    elif isinstance(spec, Mapping) and "_target_" in spec:
        cls = import_object(str(spec["_target_"]), "env.task")  # the user's own config names the class
        if not (isinstance(cls, type) and issubclass(cls, Task)):
            raise ValueError(
                f"env.task._target_={spec['_target_']!r} is not a task (rlgrasp.envs.tasks.Task)"
            )
        return cls
    elif isinstance(spec, Mapping):
        name = spec.get("name", "lift")
    else:
        raise ValueError(f"env.task must be a task name ({', '.join(TASKS)}) or a mapping, got {spec!r}")
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r} (env.task); tasks: {', '.join(TASKS)}")
    return TASKS[name]


def task_name(spec: Any) -> str:
    """The short name of the task ``spec`` names (``lift``), or its class path if it is not one of
    ``TASKS`` (a user's own)."""
    if isinstance(spec, str):
        return spec
    if isinstance(spec, Mapping) and "_target_" not in spec:
        return str(spec.get("name", "lift"))
    target = str(spec["_target_"]) if isinstance(spec, Mapping) else ""
    leaf = target.rsplit(".", 1)[-1]
    return next(
        (name for name, cls in TASKS.items() if cls.__name__ == leaf and "rlgrasp." in target), target
    )


def make_task(spec: Any, scene: Any, objects: Any) -> Task:
    """Build ``env.task`` on ``scene`` with the env's object sets; a bad keyword fails naming it."""
    cls = task_class(spec)
    keywords = (
        {k: v for k, v in dict(spec).items() if k not in ("_target_", "name")}
        if isinstance(spec, Mapping)
        else {}
    )
    try:
        return cls(scene, objects, **keywords)
    except TypeError as exc:
        raise ValueError(f"env.task ({cls.__name__}): {exc}") from None


__all__ = [
    "NOMINAL_OBJECT_XY",
    "TASKS",
    "GoalTask",
    "LiftTask",
    "PickPlaceTask",
    "PushTask",
    "RewardConfigError",
    "RewardTerms",
    "StackTask",
    "Task",
    "goal_distance",
    "make_task",
    "task_class",
    "task_name",
]
