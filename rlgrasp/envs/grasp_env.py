"""GraspEnv: the gymnasium env, given its parts (task, robot, objects, control, camera,
randomization, sim) and its config node ``EnvConfig``. Each part owns its bodies and state; the env
only sequences them."""

from __future__ import annotations

import collections
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from rlgrasp.envs.cameras import GROUND_MASK_KEY, Camera, CameraSpec, ImageHistory, object_cells
from rlgrasp.envs.collision_model import COLLISION_MODELS
from rlgrasp.envs.control import ControlConfig, make_control
from rlgrasp.envs.observation import PROPRIOCEPTION, ObservationLayout, full_parts
from rlgrasp.envs.part_config import part_config
from rlgrasp.envs.randomization import Randomizer
from rlgrasp.envs.robot import make_robot
from rlgrasp.envs.scene import MARKER_COLOUR, Scene, SimConfig
from rlgrasp.envs.tasks import Task, make_task
from rlgrasp.envs.visuals import VisualRandomizer


def _check_args(render_mode: str | None, sim: SimConfig) -> None:
    """Bad constructor values fail here, naming the key, before a physics client exists."""
    if sim.collision_model not in COLLISION_MODELS:
        raise ValueError(
            f"unknown sim.collision_model {sim.collision_model!r}; valid: {', '.join(COLLISION_MODELS)}"
        )
    modes = GraspEnv.metadata["render_modes"]
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"unknown render_mode {render_mode!r}; valid: {', '.join(modes)}")


MARKER_ALPHA = MARKER_COLOUR[3]


class GraspEnv(gym.Env):
    """A robot arm grasps an object on the ground and, per ``task``, lifts, places, pushes or stacks it.

    The env is given its parts, each a config node (``EnvConfig``) or its Python value:
    ``task`` (``rlgrasp.envs.tasks``: success, reward terms, goal), ``robot`` (a name of
    ``rlgrasp.envs.robot.ROBOTS``, ``{name: panda, model: <file>}`` for another model file of it, or a
    user's arm as ``RobotSpec`` keys: docs/robots.md), ``objects`` (the sets episodes draw from:
    ``rlgrasp.envs.objects``), ``control`` (``ControlConfig``: ``ee_delta``, ``joint_delta`` or
    ``joint_torque`` and their steps), ``camera`` (``CameraSpec`` keys, or none), ``randomization``
    (a physics preset or ranges: ``rlgrasp.envs.randomization``), ``sim`` (``SimConfig``: stepping,
    episode length, contact shapes, the visual preset, the viewer) and gymnasium's ``render_mode``.

    Observation: one float32 vector of named parts (``obs_slices``; ``rlgrasp.envs.observation``);
    a goal task's is gymnasium-robotics' ``Dict`` (``env.task.observation=dict``). With a camera it is
    a ``Dict`` of ``state`` (proprioception only), ``depth`` and/or ``rgb`` (channel first) and
    ``privileged`` (the flat state, for a teacher or a critic). Action: a Box in [-1, 1] whose last
    entry is the absolute finger-width target (-1 closed, +1 open).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 20}

    def __init__(
        self,
        task: str | Mapping[str, Any] = "lift",
        robot: str | Mapping[str, Any] = "panda",
        objects: str | list[str] | Mapping[str, Any] | None = "cube",
        control: str | Mapping[str, Any] | ControlConfig | None = None,
        camera: Mapping[str, Any] | None = None,
        randomization: str | Mapping[str, Any] | None = "default",
        sim: Mapping[str, Any] | SimConfig | None = None,
        render_mode: str | None = None,
    ):
        control = ControlConfig(mode=control) if isinstance(control, str) else control
        self.control_config = part_config(ControlConfig, control, "control")
        self.sim = part_config(SimConfig, sim, "sim")
        _check_args(render_mode, self.sim)
        camera_spec = CameraSpec.from_config(camera) if camera else None
        self.randomizer = Randomizer(randomization)
        self.max_episode_steps, self.substeps = int(self.sim.max_episode_steps), int(self.sim.substeps)
        self.render_mode = render_mode
        self.viewer = dataclasses.asdict(self.sim.viewer)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / (self.sim.time_step * self.substeps))}
        self._build_world(robot, camera_spec)
        self._build_task(objects, task)
        self.control_mode = self.control_config.mode
        self._build_control()
        self._build_spaces()

    def _build_control(self) -> None:
        """The control mode's part, on the arm just built; the world is closed if the arm refuses
        the mode (joint_torque without meaningful dynamics)."""
        try:
            self.control = make_control(self.control_config, self.robot)
        except BaseException:
            self.close()
            raise

    def _build_world(self, robot: str | Mapping[str, Any], camera_spec: CameraSpec | None) -> None:
        """The physics client, the robot (its cheap render model when a camera looks), the camera and
        the visual randomizer; the saved world each reset restores."""
        sim = self.sim
        self.scene = Scene(sim.time_step, self.render_mode == "human", sim.solver_iterations)
        self.client = self.scene.client
        try:
            render = None if camera_spec is None else "wrist" if camera_spec.mount == "wrist" else "low_poly"
            self.robot = make_robot(robot, self.client, render=render, collision=sim.collision_model)
            self.visuals = VisualRandomizer(sim.visual, self.client)
            self.camera = Camera(camera_spec, self.client) if camera_spec else None
            self.image_history = ImageHistory(camera_spec.frames if camera_spec else 1)
        except BaseException:
            self.close()
            raise
        self.robot.reset(self.robot.neutral_pose)
        if self.camera is not None:
            self._check_camera_pose()
            self._prepare_rendering()
        self.scene.save()

    def _build_task(self, objects: Any, task: Any) -> None:
        """The task part (``rlgrasp.envs.tasks``), given the scene; its goal marker only where people
        watch (a render mode)."""
        try:
            self.scene.markers_visible = self.render_mode is not None
            self.task: Task = make_task(task, self.scene, objects)
        except BaseException:
            self.close()
            raise

    def _build_spaces(self) -> None:
        self.action_dim = self.control.action_dim
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_dim,), np.float32)
        cells = self.camera.spec.object_cells if self.camera is not None else 0
        # A task's parts (a goal) after the env's own: the desired goal last, so that a goal task's
        # Dict ``observation`` is the vector without it and the parts' slices hold for both.
        parts = full_parts(self.robot.arm_dof, self.action_dim, cells) + self.task.observation_parts()
        self.layout = ObservationLayout(parts)
        self.goal_dict = self.task.goal_conditioned and getattr(self.task, "observation", "flat") == "dict"
        self.obs_slices = self.layout.slices
        self.observation_space = self._observation_space()
        self._visual_rng: np.random.Generator | None = None
        self._visual: dict[str, float] = {}
        self._idle_action = np.zeros(self.action_dim, np.float32)
        self._idle_action[-1] = 1.0  # fingers open
        self._steps = 0
        self.episode: dict[str, float] = {}
        self._readings: dict[str, Any] | None = None

    # --- gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        rng, robot = self.np_random, self.robot
        ep = self.randomizer.sample(rng)
        arm_q = np.add(robot.neutral_pose, rng.normal(0.0, ep["arm_pose_noise"], robot.arm_dof))
        self._action_offset = rng.normal(0.0, ep["action_noise_episode"], self.action_dim)
        self._obs_offset = rng.normal(0.0, ep["obs_noise_episode"], self.layout.noisy_size)
        choice = self.task.objects.draw(rng)  # last: a cube-only env draws the values it always has

        self.scene.restore(ep["gravity_z"])
        robot.set_dynamics(ep["joint_damping"], ep["finger_friction"])
        robot.reset(np.clip(arm_q, robot.lower, robot.upper))
        self.control.reset(ep)
        robot.command_fingers(robot.max_finger_width)
        self.task.reset(choice, ep, set(self.randomizer.ranges), rng)  # settles a mesh: after the robot
        self._randomize_visuals(seed)

        self._pending = collections.deque([self._idle_action.copy()] * ep["action_delay"])
        self._prev_action = self._idle_action.copy()
        self._steps = 0
        self.episode = ep
        obs, readings = self._observe(first=True)
        return obs, self._info(readings, success=False, episode=True)

    def _check_camera_pose(self) -> None:
        mount = self.robot.camera_mount() if self.camera.spec.mount == "wrist" else None
        try:
            self.camera.check_outside(self.robot.body, mount)
        except BaseException:
            self.close()
            raise

    def _prepare_rendering(self) -> None:
        """What cameras render, made cheap: no ground body for a depth-only camera (it adds the
        ground plane itself), a small one for colour, and for a wrist camera only the links it can
        see (the robot is already its low-poly model)."""
        rgb = "rgb" in self.camera.spec.keys
        if rgb:
            self.scene.use_compact_ground()
        else:
            self.scene.hide_ground()
            self.camera.ground_height = 0.0
        repaint = rgb and self.visuals.preset.ground_repaint > 0
        spec = self.camera.spec
        self.camera.segmented = repaint or spec.object_cells > 0 or spec.ground_mask
        if spec.mount == "wrist":
            self.robot.show_only(self.robot.wrist_links())

    def _randomize_visuals(self, seed: int | None) -> None:
        """Visuals draw from their own generator (derived from the reset seed), so that turning them
        on leaves the physics episodes of a seed as they are."""
        if self._visual_rng is None or seed is not None:
            self._visual_rng = np.random.default_rng(self.np_random.bit_generator.seed_seq.spawn(1)[0])
        self._visual = self.visuals.sample(self._visual_rng)
        bodies = {"object": self.scene.object, "ground": self.scene.ground}
        self.visuals.apply(self._visual, bodies, self.robot, self.camera)

    def step(self, action):
        action = np.asarray(action, dtype=np.float32).reshape(self.action_dim)
        if not np.isfinite(action).all():
            raise ValueError(f"action must be finite, got {action.tolist()}")
        # np.minimum/np.maximum: np.clip's result for finite values, at a fraction of its call cost
        action = np.minimum(np.maximum(action, -1.0), 1.0)
        # Action delay: the arm executes what the agent chose `action_delay` steps ago.
        self._pending.append(action)
        applied = self._pending.popleft()
        step_noise = self.np_random.normal(0.0, self.episode["action_noise_step"], self.action_dim)
        noise = self._action_offset + step_noise
        # The last observation's readings are the robot's state now: nothing steps between the two.
        self.control.apply(
            np.minimum(np.maximum(applied + noise, -1.0), 1.0),
            self.substeps,
            self.client.stepSimulation,
            self._readings,
        )
        self._prev_action = action
        self._steps += 1

        obs, readings = self._observe()
        reward, success = self.task.evaluate(readings)
        terminated = bool(success and self.task.terminate_on_success)
        truncated = self._steps >= self.max_episode_steps
        return obs, reward, terminated, truncated, self._info(readings, success, terminated or truncated)

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        return self.scene.viewer_image(**self.viewer)

    def close(self):
        if getattr(self, "scene", None) is not None:
            self.scene.close()
            self.scene = None

    # --- internals -----------------------------------------------------------------------------
    def _observation_space(self) -> gym.spaces.Space:
        flat = gym.spaces.Box(-np.inf, np.inf, (self.layout.size,), np.float32)
        if self.camera is None and self.goal_dict:
            goal = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
            observation = gym.spaces.Box(-np.inf, np.inf, (self.layout.size - 3,), np.float32)
            return gym.spaces.Dict({"observation": observation, "achieved_goal": goal, "desired_goal": goal})
        if self.camera is None:
            return flat
        state_size = sum(self.layout.slices[n].stop - self.layout.slices[n].start for n in self.state_parts)
        state = gym.spaces.Box(-np.inf, np.inf, (state_size,), np.float32)
        return gym.spaces.Dict({"state": state, **self.camera.spec.spaces(), "privileged": flat})

    def _observe(self, first: bool = False) -> tuple[Any, dict[str, Any]]:
        """The observation (with this step's sensor noise) and the true readings it came from;
        ``first``: an episode's first, which starts the image history."""
        if self.camera is None:
            vector, readings = self._state_vector()
            self._readings = readings
            if self.goal_dict:
                achieved = np.asarray(readings["achieved_goal"], np.float32)
                return {
                    "observation": vector[:-3],
                    "achieved_goal": achieved,
                    "desired_goal": vector[-3:],
                }, readings
            return vector, readings
        images, labels = self._render()
        vector, readings = self._state_vector(labels)
        self._readings = readings
        self.visuals.corrupt(images, self._visual, self._visual_rng)
        images = self.image_history.push(images, first)
        return {
            "state": self.layout.select(vector, self.state_parts),
            **images,
            "privileged": vector,
        }, readings

    @property
    def state_parts(self) -> tuple[str, ...]:
        """What a camera policy reads beside its images: proprioception, and a goal task's goal."""
        return (*PROPRIOCEPTION, "desired_goal") if self.task.goal_conditioned else PROPRIOCEPTION

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any = None) -> np.ndarray:
        """A goal task's sparse reward for any goals, vectorized (HER relabels with it)."""
        if not self.task.goal_conditioned:
            raise AttributeError(f"compute_reward: the task {type(self.task).__name__} has no goal")
        return self.task.compute_reward(achieved_goal, desired_goal, info)

    def _render(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The camera's images (the ground repainted where the preset says) and what its
        segmentation tells for training: the object's ``object_cells`` and the ``ground_mask`` image
        when the camera reports them."""
        mount = self.robot.camera_mount() if self.camera.spec.mount == "wrist" else None
        self.scene.set_marker_alpha(0.0)  # the goal marker is for people: the policy's camera never sees it
        images = self.camera.render(mount)
        self.scene.set_marker_alpha(MARKER_ALPHA)
        segmentation = images.pop("segmentation", None)
        repaint = self.visuals.preset.ground_repaint > 0
        needs_ground = segmentation is not None and (repaint or self.camera.spec.ground_mask)
        ground = segmentation == self.scene.ground if needs_ground else None
        if ground is not None and repaint:
            self.visuals.repaint_ground(images, ground, self._visual_rng)
        if self.camera.spec.ground_mask:
            images[GROUND_MASK_KEY] = ground.astype(np.uint8)[None]
        cells = self.camera.spec.object_cells
        labels = {"object_cells": object_cells(segmentation == self.scene.object, cells)} if cells else {}
        return images, labels

    def _state_vector(
        self, labels: Mapping[str, np.ndarray] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """The flat state (with this step's sensor noise) and the true readings it came from;
        ``labels``: readings a camera's image gave (``_render``)."""
        robot = self.robot
        readings = robot.readings()
        readings.update(self.task.readings(readings["grasp_pos"], robot.body, robot.finger_links))
        readings["prev_action"] = self._prev_action
        readings.update(labels or {})
        obs = self.layout.assemble(readings)
        ep = self.episode
        if ep["obs_noise_step"] > 0 or ep["obs_noise_episode"] > 0:
            step_noise = self.np_random.normal(0.0, ep["obs_noise_step"], self.layout.noisy_size)
            self.layout.add_noise(obs, self._obs_offset + step_noise)
        return obs, readings

    def _info(self, readings: dict[str, Any], success: bool, episode: bool) -> dict[str, Any]:
        """Every step's readings; the episode's object and draws only at its first and last step.

        A vector env stacks every key of every env's info at each step: the 20-odd draws every step
        cost training frames/s, for values that change only at a reset
        (docs/history/throughput.md#the-episodes-draws-out-of-every-steps-info).
        """
        info = {**self.task.info(readings, success), **self.randomizer.info()}
        if episode:
            info.update(self.task.episode_info(), randomization={**self.episode, **self._visual})
        return info

    def set_randomization_ranges(self, ranges: Mapping[str, Any], boundary_prob: float) -> None:
        """ADR's current ranges, from the learner between batches (``rlgrasp.train.collection.adr_sync``)."""
        self.randomizer.set_ranges(ranges, boundary_prob)

    # --- what tools read -------------------------------------------------------------------------
    @property
    def object_name(self) -> str:
        return self.task.object_name

    @property
    def object_extents(self) -> np.ndarray:
        return self.task.object_extents


@dataclass
class EnvConfig:
    """``env``: ``GraspEnv``'s constructor as a ``_target_`` node, one field per part.

    Built everywhere with ``hydra.utils.instantiate(cfg.env, _partial_=True)`` (see
    ``rlgrasp.envs.factory.env_factory``); a test checks that the fields mirror the constructor. The
    config groups set the parts: ``task=``, ``robot=``, ``objects=``, ``cameras=``,
    ``randomization=``, ``visual=`` (``env.sim.visual``).
    """

    _target_: str = "rlgrasp.envs.PandaGraspEnv"
    # A `_target_` node of rlgrasp.envs.tasks (lift, pick_place, push, stack, or a task class of your
    # own) with its keywords, e.g. env.task.reward=sparse. Typed Any: each task checks its own keywords.
    task: Any = "lift"
    # An arm of rlgrasp.envs.robot.ROBOTS, {name: panda, model: <file>}, or a user's arm as a mapping
    # of rlgrasp.envs.robot_spec.RobotSpec keys (docs/robots.md).
    robot: Any = "panda"
    # A set name, a list of set names, or a mapping with sets / paths / max_width / scale
    # (rlgrasp/envs/objects.py).
    objects: Any = "cube"
    control: ControlConfig = field(default_factory=ControlConfig)
    camera: Any = None  # null, or rlgrasp.envs.cameras.CameraSpec keys (the `cameras` group)
    randomization: Any = "default"  # a preset name (the `randomization` group) or a mapping of ranges
    sim: SimConfig = field(default_factory=SimConfig)
    render_mode: str | None = None
