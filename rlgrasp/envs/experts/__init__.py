"""Scripted experts, one per task, each acting only through ``ee_delta`` actions and the observation.

They prove a task solvable under each randomization preset, are the baseline a learned policy is
compared with, and record demonstrations. ``expert_for(env)`` is the expert of the env's task:

- ``lift`` (``ScriptedExpert``, ``lift.py``): approach, descend, close, lift;
- ``pick_place`` (``PickPlaceExpert``, ``pick_place.py``): the same grasp, then carry the object's
  centre to the goal and hold it there;
- ``push`` (``PushExpert``, ``push.py``): fingers closed, behind the object opposite the goal at low
  height, push; back up and round when it drifts off the line;
- ``stack`` (``StackExpert``, ``stack.py``): the grasp, carry above the base cube, lower onto it,
  open the fingers and move up.

Each reads the flat vector, a goal task's Dict or a camera env's ``privileged`` entry alike
(``flat_observation``).
"""

from __future__ import annotations

from typing import Any

from rlgrasp.envs.experts.lift import ScriptedExpert, grasp_plan
from rlgrasp.envs.experts.observation import flat_observation
from rlgrasp.envs.experts.pick_place import PickPlaceExpert
from rlgrasp.envs.experts.push import PushExpert
from rlgrasp.envs.experts.stack import StackExpert
from rlgrasp.envs.tasks import LiftTask, PickPlaceTask, PushTask, StackTask

#: The expert of each task class (a subclass of a task gets its parent's expert). Stack before
#: pick-and-place: the most specific class first.
EXPERTS: tuple[tuple[type, type[ScriptedExpert]], ...] = (
    (StackTask, StackExpert),
    (PushTask, PushExpert),
    (PickPlaceTask, PickPlaceExpert),
    (LiftTask, ScriptedExpert),
)


def expert_class(task: Any) -> type[ScriptedExpert]:
    """The expert class of ``task`` (a task object); a task no expert knows is a ``ValueError``."""
    for task_type, expert in EXPERTS:
        if isinstance(task, task_type):
            return expert
    known = ", ".join(t.__name__ for t, _ in EXPERTS)
    raise ValueError(f"no scripted expert for the task {type(task).__name__} (experts exist for {known})")


def expert_for(env: Any, **settings: Any) -> ScriptedExpert:
    """The scripted expert of ``env``'s task (``env`` a grasp env or a wrapper of one), with the arm's
    grasp settings unless ``settings`` give them (``ScriptedExpert.for_env``)."""
    base = getattr(env, "unwrapped", env)
    return expert_class(base.task).for_env(env, **settings)


__all__ = [
    "EXPERTS",
    "PickPlaceExpert",
    "PushExpert",
    "ScriptedExpert",
    "StackExpert",
    "expert_class",
    "expert_for",
    "flat_observation",
    "grasp_plan",
]
