"""GraspEnv: the gymnasium env, built from a scene, a robot, a control mode, a task, a randomizer
and an observation layout. Each part owns its bodies and state; the env only sequences them."""

from __future__ import annotations

import collections
import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from rlgrasp.envs.cameras import GROUND_MASK_KEY, Camera, CameraSpec, ImageHistory, object_cells
from rlgrasp.envs.collision_model import COLLISION_MODELS
from rlgrasp.envs.control import CONTROL_MODES, make_control
from rlgrasp.envs.observation import PROPRIOCEPTION, ObservationLayout, full_parts
from rlgrasp.envs.randomization import Randomizer
from rlgrasp.envs.robot import make_robot
from rlgrasp.envs.scene import MARKER_COLOUR, Scene
from rlgrasp.envs.tasks import Task, make_task
from rlgrasp.envs.visuals import VisualRandomizer


def _check_args(
    control_mode: str,
    render_mode: str | None,
    max_episode_steps: int,
    substeps: int,
    time_step: float,
    collision_model: str,
) -> None:
    """Bad constructor values fail here, naming the argument, before a physics client exists."""
    if control_mode not in CONTROL_MODES:
        raise ValueError(f"unknown control_mode {control_mode!r}; valid modes: {', '.join(CONTROL_MODES)}")
    if collision_model not in COLLISION_MODELS:
        raise ValueError(f"unknown collision_model {collision_model!r}; valid: {', '.join(COLLISION_MODELS)}")
    modes = GraspEnv.metadata["render_modes"]
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"unknown render_mode {render_mode!r}; valid: {', '.join(modes)}")
    for name, value in (("max_episode_steps", max_episode_steps), ("substeps", substeps)):
        if int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if not (time_step > 0 and math.isfinite(time_step)):
        raise ValueError(f"time_step must be a positive number, got {time_step!r}")


MARKER_ALPHA = MARKER_COLOUR[3]


class GraspEnv(gym.Env):
    """A robot arm grasps an object on the ground and lifts it.

    ``objects`` says which objects episodes draw (``rlgrasp.envs.objects``; default the cube),
    ``robot`` which arm (a name of ``rlgrasp.envs.robot.ROBOTS``, or a user's arm as a mapping of
    ``rlgrasp.envs.robot_spec.RobotSpec`` keys: docs/robots.md). Observation: one float32 vector of named
    parts (``obs_slices``; ``rlgrasp.envs.observation``): ``object_pos``/``object_quat`` are the
    object's base (centre of mass) pose, ``object_minus_grasp`` is its bounding-box centre minus the
    grasp point and ``object_extents`` the bounding box's size in the object's own frame.
    Action: a Box in [-1, 1]; the last entry is the absolute finger-width target (-1 closed,
    +1 open); the others depend on ``control_mode`` (``rlgrasp.envs.control``): ``ee_delta``,
    ``joint_delta`` or ``joint_torque``.

    With a ``camera`` (``rlgrasp.envs.cameras.CameraSpec`` keys) the observation is a ``Dict``:
    ``state`` (proprioception only: nothing about the object), ``depth`` and/or ``rgb`` (channel
    first) and ``privileged`` (the flat state vector above, for a teacher or a critic). ``visual``
    names a visual randomization preset (``rlgrasp.envs.visuals``). ``collision_model``: ``mesh`` (the
    arm's own collision meshes) or ``primitive`` (boxes and capsules for the hand and fingers:
    ``rlgrasp.envs.collision_model``; the shipped policies were trained on the meshes).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 20}

    def __init__(
        self,
        control_mode: str = "ee_delta",
        randomization: str | Mapping[str, Any] | None = "default",
        max_episode_steps: int = 50,
        time_step: float = 1.0 / 240.0,
        substeps: int = 12,
        task: str | Mapping[str, Any] = "lift",
        ee_step: float = 0.04,
        ee_yaw: bool = False,
        yaw_step: float = 0.2,
        joint_step: float = 0.05,
        torque_fraction: float = 0.3,
        gravity_compensation: bool = True,
        render_mode: str | None = None,
        render_width: int = 320,
        render_height: int = 240,
        camera_distance: float = 1.1,
        camera_yaw: float = 60.0,
        camera_pitch: float = -25.0,
        solver_iterations: int = 20,
        robot: str | Mapping[str, Any] = "panda",
        robot_urdf: str | None = None,
        objects: str | list[str] | Mapping[str, Any] | None = "cube",
        camera: Mapping[str, Any] | None = None,
        visual: str | None = "none",
        collision_model: str = "mesh",
    ):
        _check_args(control_mode, render_mode, max_episode_steps, substeps, time_step, collision_model)
        camera_spec = CameraSpec.from_config(camera) if camera else None
        self.randomizer = Randomizer(randomization)
        self.max_episode_steps, self.substeps = int(max_episode_steps), int(substeps)
        self.render_mode = render_mode
        self.viewer = dict(
            width=render_width,
            height=render_height,
            distance=camera_distance,
            yaw=camera_yaw,
            pitch=camera_pitch,
        )
        self.metadata = {**self.metadata, "render_fps": round(1.0 / (time_step * substeps))}

        self._build_world(
            time_step, solver_iterations, robot, robot_urdf, camera_spec, visual, collision_model
        )
        self._build_task(objects, task)
        self.control_mode = control_mode
        self._build_control(
            ee_step=ee_step,
            ee_yaw=ee_yaw,
            yaw_step=yaw_step,
            joint_step=joint_step,
            torque_fraction=torque_fraction,
            gravity_compensation=gravity_compensation,
        )
        self._build_spaces()

    def _build_control(self, **settings: Any) -> None:
        """The control mode's part, on the arm just built; the world is closed if the arm refuses
        the mode (joint_torque without meaningful dynamics)."""
        try:
            self.control = make_control(self.control_mode, self.robot, **settings)
        except BaseException:
            self.close()
            raise

    def _build_world(
        self,
        time_step: float,
        solver_iterations: int,
        robot: str | Mapping[str, Any],
        robot_urdf: str | None,
        camera_spec: CameraSpec | None,
        visual: str | None,
        collision_model: str,
    ) -> None:
        """The physics client, the robot (its cheap render model when a camera looks), the camera and
        the visual randomizer; the saved world each reset restores."""
        self.scene = Scene(time_step, gui=self.render_mode == "human", solver_iterations=solver_iterations)
        self.client = self.scene.client
        try:
            render = None if camera_spec is None else "wrist" if camera_spec.mount == "wrist" else "low_poly"
            self.robot = make_robot(robot, self.client, robot_urdf, render, collision_model)
            self.visuals = VisualRandomizer(visual, self.client)
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
        (docs/benchmarks/throughput.md#the-episodes-draws-out-of-every-steps-info).
        """
        info = {**self.task.info(readings, success), **self.randomizer.info()}
        if episode:
            info.update(self.task.episode_info(), randomization={**self.episode, **self._visual})
        return info

    def set_randomization_ranges(self, ranges: Mapping[str, Any], boundary_prob: float) -> None:
        """ADR's current ranges, from the learner between batches (``rlgrasp.train.adr_sync``)."""
        self.randomizer.set_ranges(ranges, boundary_prob)

    # --- what tools read -------------------------------------------------------------------------
    @property
    def object_name(self) -> str:
        return self.task.object_name

    @property
    def object_extents(self) -> np.ndarray:
        return self.task.object_extents
