"""What every task shares: the episode's object (drawn, placed, measured) and the reward terms.

Like panda-gym's ``Task``, a task places its own bodies on reset (the object drawn from the object
sets, at the drawn pose and dynamics), so the env only resets the robot and then the task. A task
says what success is (``succeeded``), names its reward term sets (``TERM_SETS``) and the term
functions they may use (``TERMS``), and may add parts to the observation (``observation_parts``:
a goal task's goal). Its constructor's keywords are its config (``env.task``): checked here, with
one line naming the key, before any worker starts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from rlgrasp.envs.objects import ObjectChoice, ObjectSampler, snap_scale, tilt
from rlgrasp.envs.observation import Part
from rlgrasp.envs.scene import Scene
from rlgrasp.envs.tasks.terms import RewardTerms, TermFn

NOMINAL_OBJECT_XY = (0.6, 0.0)  # below the grasp point at the neutral pose


class Task:
    """The episode's object and the reward; subclasses say what success is."""

    #: Each term set a config may name (``env.task.reward: dense``): terms and normalization.
    TERM_SETS: ClassVar[dict[str, dict[str, Any]]] = {}
    #: The term functions a term set may use by name.
    TERMS: ClassVar[dict[str, TermFn]] = {}
    #: The term set used when the config names none.
    DEFAULT_REWARD: ClassVar[str] = "dense"
    #: The observation of a goal task is a Dict (``observation``, ``achieved_goal``, ``desired_goal``).
    goal_conditioned: ClassVar[bool] = False

    def __init__(
        self,
        scene: Scene,
        objects: Any = "cube",
        reward: Any = None,
        weights: Mapping[str, float] | None = None,
        terminate_on_success: bool = False,
    ):
        self.scene, self.client = scene, scene.client
        self.objects = objects if isinstance(objects, ObjectSampler) else ObjectSampler(objects)
        reward = self.DEFAULT_REWARD if reward is None else reward
        self.reward_name = reward if isinstance(reward, str) else "custom"
        self.reward = RewardTerms(reward, self.TERM_SETS, self.TERMS, weights)
        self.terminate_on_success = bool(terminate_on_success)
        self.object_name = ""
        self.object_extents = np.zeros(3, np.float32)
        self._offset = np.zeros(3)
        self._has_offset = False
        self.rest_z = 0.0
        self.settle_substeps = 0

    # --- what subclasses say -------------------------------------------------------------------
    def succeeded(self, readings: Mapping[str, Any]) -> bool:
        raise NotImplementedError

    def observation_parts(self) -> list[Part]:
        """Parts the task adds after the env's own (a goal task: its goal)."""
        return []

    def sample_goal(self, rng: np.random.Generator) -> None:
        """A goal task draws its goal here, after the object is placed."""

    # --- the object ----------------------------------------------------------------------------
    def reset(
        self,
        choice: ObjectChoice,
        episode: dict[str, Any],
        randomized: set[str],
        rng: np.random.Generator | None = None,
    ) -> None:
        """Place the drawn object, then (a goal task) draw the goal; the reward's sums restart."""
        self.place_object(choice, episode, randomized)
        if rng is not None:
            self.sample_goal(rng)
        self.reward.reset()

    def place_object(self, choice: ObjectChoice, episode: dict[str, Any], randomized: set[str]) -> None:
        """Build the drawn object upright at the drawn pose with the drawn (or its own) dynamics.

        ``randomized``: the parameters the randomizer draws; mass and friction it leaves alone are the
        object's own. ``episode`` gains the values actually used (snapped scale, own mass).
        """
        scale = episode["object_size_scale"] = snap_scale(episode["object_size_scale"])
        geometry = self.objects.geometry(choice)
        self.object_name = f"cube/{scale:.1f}" if choice.name == "cube" else choice.name
        self.object_extents = np.array(geometry.extents, np.float32) * np.float32(scale)
        self._offset = np.array(geometry.offset) * scale
        self._has_offset = bool(self._offset.any())  # read every step: asked once an episode
        self.rest_z = geometry.rest_height * scale
        self.settle_substeps = 0
        xy = np.add(NOMINAL_OBJECT_XY, (episode["object_x"], episode["object_y"]))
        quat = self.client.getQuaternionFromEuler((0.0, 0.0, episode["object_yaw"]))
        body = self.scene.spawn(choice, scale, [xy[0], xy[1], self.rest_z], quat)
        if "object_mass" not in randomized:
            episode["object_mass"] = geometry.mass
        if "object_lateral_friction" not in randomized:
            episode["object_lateral_friction"] = geometry.lateral_friction
        self.client.changeDynamics(
            body,
            -1,
            mass=episode["object_mass"],
            lateralFriction=episode["object_lateral_friction"],
            spinningFriction=episode["object_spinning_friction"],
            rollingFriction=episode["object_rolling_friction"],
            restitution=episode["object_restitution"],
        )
        if choice.kind in ("mesh", "urdf") and choice.name != "cube":
            self._settle()

    def _settle(self, max_substeps: int = 48, speed: float = 5e-3) -> None:
        """Let a mesh come to rest and take its height then as its rest height.

        A mesh's bounding box says where its lowest point is, not whether it stands: many
        random_urdfs rock or tip onto a flatter side. Heights are measured from where it settled.
        Those substeps simulate the robot too: reset the robot first.
        """
        c, body = self.client, self.scene.object
        for i in range(max_substeps):
            c.stepSimulation()
            if i >= 8:
                linear, angular = c.getBaseVelocity(body)
                if max(map(abs, linear)) < speed and max(map(abs, angular)) < 10 * speed:
                    break
        self.settle_substeps = i + 1
        self.rest_z = c.getBasePositionAndOrientation(body)[0][2]

    # --- measuring -----------------------------------------------------------------------------
    def grasped(self, robot_body: int, finger_links: list[int]) -> bool:
        """Both fingers touch the object."""
        body, contacts = self.scene.object, self.client.getContactPoints
        return all(contacts(bodyA=robot_body, bodyB=body, linkIndexA=link) for link in finger_links)

    def readings(self, grasp_pos: np.ndarray, robot_body: int, finger_links: list[int]) -> dict[str, Any]:
        """The object's state by observation part name (privileged: no robot senses it directly)."""
        c, body = self.client, self.scene.object
        object_pos, object_quat = c.getBasePositionAndOrientation(body)
        object_linvel, object_angvel = c.getBaseVelocity(body)
        object_pos = np.array(object_pos)
        centre = object_pos
        if self._has_offset:
            rotation = np.array(c.getMatrixFromQuaternion(object_quat)).reshape(3, 3)
            centre = object_pos + rotation @ self._offset
        grasped = self.grasped(robot_body, finger_links)
        return {
            "object_pos": object_pos,
            "object_quat": object_quat,
            "object_linvel": object_linvel,
            "object_angvel": object_angvel,
            "object_minus_grasp": centre - grasp_pos,
            "object_extents": self.object_extents,
            "grasped": np.array([float(grasped)]),
            "object_centre": centre,
        }

    def evaluate(self, readings: Mapping[str, Any]) -> tuple[float, bool]:
        """The step's reward (its terms' weighted sum) and success."""
        return self.reward(self, readings), self.succeeded(readings)

    def info(self, readings: Mapping[str, Any], success: bool) -> dict[str, Any]:
        """What changes every step; ``reward_terms``: each term's sum so far this episode."""
        # numpy scalars, not Python ones: TorchRL's info reader needs a dtype.
        return {
            "is_success": np.bool_(success),
            "grasped": np.bool_(readings["grasped"][0] > 0.5),
            "lift_height": np.float32(readings["object_pos"][2] - self.rest_z),
            "object_tilt": np.float32(tilt(readings["object_quat"])),
            "reward_terms": self.reward.episode_sums.copy(),
        }

    def episode_info(self) -> dict[str, Any]:
        """What the episode fixed when it began."""
        return {"object": self.object_name, "object_extents": self.object_extents.copy()}
