"""Goal tasks in the gymnasium-robotics / panda-gym convention: pick-and-place, push and stack.

The observation is a ``Dict`` of ``observation`` (the env's flat state), ``achieved_goal`` (where the
object is) and ``desired_goal`` (where it should be); ``compute_reward(achieved_goal, desired_goal,
info)`` is vectorized and ``info["is_success"]`` says whether the object is within
``distance_threshold`` of the goal, so that hindsight relabelling (HER) and other goal tools work
unchanged. The sparse reward (the default) pays 1 while the goal is met, 0 otherwise (rlgrasp's
sparse lift pays the same; panda-gym pays -1 / 0: the same signal shifted by one). ``dense`` is a
term set (reach, grasp, place, success) for learners without HER. A goal the arm cannot reach is
refused at construction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rlgrasp.envs.objects import ObjectChoice
from rlgrasp.envs.observation import Part
from rlgrasp.envs.tasks.base import NOMINAL_OBJECT_XY, Task
from rlgrasp.envs.tasks.terms import grasp, reach, success

#: How far from the arm's base (at the origin) a goal may lie, and how high: the arms' workspace.
MAX_GOAL_RADIUS = 0.8
MAX_GOAL_HEIGHT = 0.3
#: Redraws before a goal is accepted however close it lies to the object's start.
GOAL_REDRAWS = 20


def goal_distance(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """Euclidean distance over the last axis (vectorized, as HER calls it on batches)."""
    return np.linalg.norm(np.asarray(achieved) - np.asarray(desired), axis=-1)


def place(task: Any, readings: Mapping[str, Any], scale: float = 5.0, held: bool = True) -> float:
    """1 - tanh(scale x the object's distance to the goal); with ``held``, 0 unless grasped."""
    if held and readings["grasped"][0] <= 0.5:
        return 0.0
    return 1.0 - math.tanh(scale * float(goal_distance(readings["achieved_goal"], readings["desired_goal"])))


def _check_range(name: str, value: Any, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=float).reshape(-1)
    if array.size != size or not np.all(np.isfinite(array)) or np.any(array < 0):
        raise ValueError(f"env.task.{name} must be {size} finite numbers >= 0, got {value!r}")
    return array


class GoalTask(Task):
    """The object to a goal drawn each episode; success within ``distance_threshold``."""

    goal_conditioned = True
    DEFAULT_REWARD = "sparse"
    TERMS = {"reach": reach, "grasp": grasp, "place": place, "place_fine": place, "success": success}
    # The dense set as Isaac Lab's Franka lift-to-goal writes it: a coarse goal term that pulls from
    # afar, a fine one (scale 20: half its value within 3 cm) that pays for precision inside the
    # success radius, and the goal terms outweighing the approach. With one coarse term (scale 5,
    # weight 2 of 5) the learned policies reached the goal but drifted back out before the episode's
    # end: inside 5 cm that term changed by 0.02 a step per centimetre (docs/tasks.md).
    TERM_SETS = {
        "sparse": {"terms": {"success": {"weight": 1.0}}, "normalize": True},
        "dense": {
            "terms": {
                "reach": {"weight": 1.0},
                "grasp": {"weight": 1.0},
                "place": {"weight": 4.0},
                "place_fine": {"weight": 2.0, "scale": 20.0},
                "success": {"weight": 2.0},
            },
            "normalize": True,
        },
    }

    def __init__(
        self,
        scene: Any,
        objects: Any = "cube",
        goal_range: Sequence[float] = (0.15, 0.15),
        goal_height: float = 0.0,
        air_fraction: float = 0.0,
        min_goal_distance: float = 0.08,
        distance_threshold: float = 0.05,
        observation: str = "dict",
        **task: Any,
    ):
        if observation not in ("dict", "flat"):
            raise ValueError(
                f"env.task.observation must be dict (observation / achieved_goal / desired_goal, for HER) "
                f"or flat (the goal appended to one vector, for learners that read one), got {observation!r}"
            )
        self.observation = observation
        self.goal_range = _check_range("goal_range", goal_range, 2)
        self.goal_height = float(_check_range("goal_height", goal_height, 1)[0])
        self.air_fraction, self.min_goal_distance = float(air_fraction), float(min_goal_distance)
        self.distance_threshold = float(distance_threshold)
        if not 0.0 <= self.air_fraction <= 1.0:
            raise ValueError(f"env.task.air_fraction must be in [0, 1], got {air_fraction!r}")
        if not self.distance_threshold > 0:
            raise ValueError(f"env.task.distance_threshold must be > 0, got {distance_threshold!r}")
        self._check_reach()
        super().__init__(scene, objects, **task)
        self.goal = np.zeros(3)
        self.marker: int | None = None

    def _check_reach(self) -> None:
        """A goal range the arm cannot reach is refused naming the key (the nominal object place is
        at x = 0.6 m from the arm's base)."""
        far = math.hypot(
            NOMINAL_OBJECT_XY[0] + self.goal_range[0], abs(NOMINAL_OBJECT_XY[1]) + self.goal_range[1]
        )
        if far > MAX_GOAL_RADIUS:
            raise ValueError(
                f"env.task.goal_range={self.goal_range.tolist()} puts goals {far:.2f} m from the arm's base; "
                f"the arms reach {MAX_GOAL_RADIUS} m (keep |x|, |y| offsets within about 0.15-0.2 m)"
            )
        if self.goal_height > MAX_GOAL_HEIGHT:
            raise ValueError(
                f"env.task.goal_height={self.goal_height} is above what the arms reach over the table "
                f"(at most {MAX_GOAL_HEIGHT} m)"
            )

    # --- the goal ------------------------------------------------------------------------------
    def sample_goal(self, rng: np.random.Generator) -> None:
        """A goal on the table (or, ``air_fraction`` of the time, up to ``goal_height`` above it), at
        least ``min_goal_distance`` from where the object starts when a few draws allow it."""
        start = np.array(self.client.getBasePositionAndOrientation(self.scene.object)[0])
        for _ in range(GOAL_REDRAWS):
            xy = np.add(NOMINAL_OBJECT_XY, rng.uniform(-self.goal_range, self.goal_range))
            z = self.rest_z
            if self.air_fraction > 0 and rng.uniform() < self.air_fraction:
                z += rng.uniform(0.0, self.goal_height)
            goal = np.array([xy[0], xy[1], z])
            if goal_distance(goal, start) >= self.min_goal_distance:
                break
        self.goal = goal
        self.scene.show_marker(goal)

    def observation_parts(self) -> list[Part]:
        return [Part("desired_goal", 3, noisy=False)]

    def readings(self, grasp_pos: np.ndarray, robot_body: int, finger_links: list[int]) -> dict[str, Any]:
        readings = super().readings(grasp_pos, robot_body, finger_links)
        readings["achieved_goal"] = readings["object_pos"]
        readings["desired_goal"] = self.goal
        return readings

    def succeeded(self, readings: Mapping[str, Any]) -> bool:
        return bool(
            goal_distance(readings["achieved_goal"], readings["desired_goal"]) < self.distance_threshold
        )

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any = None) -> np.ndarray:
        """The sparse reward for any goals (vectorized): 1.0 within ``distance_threshold``, else 0.0.
        It equals the step's reward under ``reward: sparse``; HER relabels with it."""
        return (goal_distance(achieved_goal, desired_goal) < self.distance_threshold).astype(np.float32)

    def info(self, readings: Mapping[str, Any], success: bool) -> dict[str, Any]:
        info = super().info(readings, success)
        info["goal_distance"] = np.float32(goal_distance(readings["achieved_goal"], readings["desired_goal"]))
        return info


class PickPlaceTask(GoalTask):
    """Pick the object up and put it at the goal: on the table or, half the time, up to 20 cm above."""

    def __init__(
        self, scene: Any, objects: Any = "cube", goal_height: float = 0.2, air_fraction: float = 0.5, **task
    ):
        super().__init__(scene, objects, goal_height=goal_height, air_fraction=air_fraction, **task)


def behind(task: Any, readings: Mapping[str, Any], scale: float = 5.0, standoff: float = 0.05) -> float:
    """1 - tanh(scale x the grasp point's distance to the spot ``standoff`` behind the object's centre,
    on the side away from the goal): a push needs the hand there, where ``reach`` pulls it to the
    object from any side (and pushes it off the line as often as along it)."""
    centre = readings["object_centre"]
    to_goal = np.asarray(readings["desired_goal"][:2]) - centre[:2]
    distance = math.hypot(*to_goal)
    spot = centre.copy()
    if distance > 1e-6:
        spot[:2] -= to_goal / distance * standoff
    offset = spot - readings["grasp_pos"]
    return 1.0 - math.tanh(scale * math.sqrt(offset.dot(offset)))


class PushTask(GoalTask):
    """Slide the object to a goal on the table; the gripper may stay closed."""

    TERMS = {**GoalTask.TERMS, "behind": behind}
    TERM_SETS = {
        **GoalTask.TERM_SETS,
        "dense": {
            "terms": {
                "behind": {"weight": 1.0},
                "place": {"weight": 4.0, "held": False},
                "place_fine": {"weight": 2.0, "scale": 20.0, "held": False},
                "success": {"weight": 2.0},
            },
            "normalize": True,
        },
    }

    def __init__(self, scene: Any, objects: Any = "cube", **task: Any):
        super().__init__(scene, objects, goal_height=0.0, air_fraction=0.0, **task)


BASE_COLOUR = (0.25, 0.45, 0.85, 1.0)


def release(task: Any, readings: Mapping[str, Any], scale: float = 5.0) -> float:
    """1 - tanh(scale x distance to the goal) once the fingers are off the object: let go on top."""
    if readings["grasped"][0] > 0.5:
        return 0.0
    return 1.0 - math.tanh(scale * float(goal_distance(readings["achieved_goal"], readings["desired_goal"])))


class StackTask(GoalTask):
    """Put the object (the top cube) onto a second cube (the base) and let go.

    The base is placed at a drawn spot at least ``min_goal_distance`` from the object; the goal is
    the top cube's centre resting on the base. Success: the top cube within ``distance_threshold``
    of that spot, the fingers off it, and the base where it was put (within ``base_tolerance``).
    3 cm, not 2: a cube resting on the base at its height is stacked when it sits up to about half
    a cube's width off the centre, and the base may have shifted by up to ``base_tolerance``
    (docs/tasks.md#the-scripted-experts; panda-gym's stack takes 5 cm).
    """

    TERMS = {**GoalTask.TERMS, "release": release}
    # The goal terms pay whether the cube is held or not: paid only while held (pick-and-place's),
    # they made letting go on the base cost more than success and release pay, and the learned
    # policy held the cube over the base to the end (docs/tasks.md).
    TERM_SETS = {
        **GoalTask.TERM_SETS,
        "dense": {
            "terms": {
                "reach": {"weight": 1.0},
                "grasp": {"weight": 1.0},
                "place": {"weight": 4.0, "held": False},
                "place_fine": {"weight": 2.0, "scale": 20.0, "held": False},
                "success": {"weight": 2.0},
                "release": {"weight": 1.0},
            },
            "normalize": True,
        },
    }

    def __init__(
        self,
        scene: Any,
        objects: Any = "cube",
        distance_threshold: float = 0.03,
        base_tolerance: float = 0.02,
        **task: Any,
    ):
        super().__init__(scene, objects, distance_threshold=distance_threshold, **task)
        self.base_tolerance = float(base_tolerance)
        self.base_start = np.zeros(3)

    def sample_goal(self, rng: np.random.Generator) -> None:
        """The base cube at a drawn spot on the table; the goal on top of it."""
        start = np.array(self.client.getBasePositionAndOrientation(self.scene.object)[0])
        half = float(self.object_extents[2]) / 2
        for _ in range(GOAL_REDRAWS):
            xy = np.add(NOMINAL_OBJECT_XY, rng.uniform(-self.goal_range, self.goal_range))
            if math.hypot(*(xy - start[:2])) >= max(self.min_goal_distance, 0.09):
                break
        base = ObjectChoice("cube", "box", dims=(0.05, 0.05, 0.05))
        self.base_start = np.array([xy[0], xy[1], 0.025])
        body = self.scene.spawn_extra(base, 1.0, self.base_start, (0.0, 0.0, 0.0, 1.0), colour=BASE_COLOUR)
        self.client.changeDynamics(body, -1, mass=0.5, lateralFriction=1.0)
        self.goal = self.base_start + [0.0, 0.0, 0.025 + half]
        self.scene.show_marker(self.goal)

    def readings(self, grasp_pos: np.ndarray, robot_body: int, finger_links: list[int]) -> dict[str, Any]:
        readings = super().readings(grasp_pos, robot_body, finger_links)
        base_pos = np.array(self.client.getBasePositionAndOrientation(self.scene.extras[0])[0])
        readings["base_pos"] = base_pos
        readings["base_moved"] = float(goal_distance(base_pos, self.base_start))
        return readings

    def observation_parts(self) -> list[Part]:
        return [Part("base_pos", 3), Part("desired_goal", 3, noisy=False)]  # the goal last (Dict)

    def succeeded(self, readings: Mapping[str, Any]) -> bool:
        placed = super().succeeded(readings)
        return bool(placed and readings["grasped"][0] <= 0.5 and readings["base_moved"] < self.base_tolerance)
