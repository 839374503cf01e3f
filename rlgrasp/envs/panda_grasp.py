"""PandaGraspEnv: the gymnasium env that ties scene, robot, task and randomizer together."""

from __future__ import annotations

import collections
import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from rlgrasp.envs.objects import ObjectSampler, snap_scale, tilt
from rlgrasp.envs.randomization import Randomizer
from rlgrasp.envs.robot import MAX_FINGER_WIDTH, NEUTRAL_POSE, Panda
from rlgrasp.envs.scene import Scene
from rlgrasp.envs.task import LiftTask, RewardWeights

CONTROL_MODES = ("ee_delta", "joint_delta", "joint_torque")
NOMINAL_OBJECT_XY = (0.6, 0.0)  # below the grasp point at the neutral pose
WORKSPACE_LOW = np.array([0.3, -0.35, 0.005])  # grasp-point targets are clipped to this box;
WORKSPACE_HIGH = np.array([0.85, 0.35, 0.45])  # the z floor keeps the fingertips off the ground


def _observation_layout(action_dim: int) -> dict[str, int]:
    return {
        "arm_q": 7,
        "arm_qd": 7,
        "finger_width": 1,
        "grasp_pos": 3,
        "grasp_vel": 3,
        "object_pos": 3,
        "object_quat": 4,
        "object_linvel": 3,
        "object_angvel": 3,
        "object_minus_grasp": 3,
        "object_extents": 3,
        "grasped": 1,
        "prev_action": action_dim,
    }


def _check_args(
    control_mode: str, render_mode: str | None, max_episode_steps: int, substeps: int, time_step: float
) -> None:
    """Bad constructor values fail here, naming the argument, before a physics client exists."""
    if control_mode not in CONTROL_MODES:
        raise ValueError(f"unknown control_mode {control_mode!r}; valid modes: {', '.join(CONTROL_MODES)}")
    modes = PandaGraspEnv.metadata["render_modes"]
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"unknown render_mode {render_mode!r}; valid: {', '.join(modes)}")
    for name, value in (("max_episode_steps", max_episode_steps), ("substeps", substeps)):
        if int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    if not (time_step > 0 and math.isfinite(time_step)):
        raise ValueError(f"time_step must be a positive number, got {time_step!r}")


class PandaGraspEnv(gym.Env):
    """A Franka Panda grasps an object on the ground and lifts it.

    ``objects`` says which objects episodes draw (``rlgrasp.envs.objects``; default the cube).
    Observation: one float32 vector whose parts are named in ``obs_slices`` (see
    ``_observation_layout``): ``object_pos``/``object_quat`` are the object's base (centre of mass)
    pose, ``object_minus_grasp`` is its bounding-box centre minus the grasp point and
    ``object_extents`` the bounding box's size in the object's own frame.
    Action: a Box in [-1, 1]; the last entry is always the absolute
    finger-width target (-1 closed, +1 open). ``control_mode``:

    - ``ee_delta``: grasp-point (dx, dy, dz[, dyaw]) x ``ee_step``, solved by IK, gripper down.
    - ``joint_delta``: 7 arm joint deltas x ``joint_step`` rad.
    - ``joint_torque``: 7 torques x ``torque_fraction`` of each joint's effort limit, re-sent
      every physics substep, plus gravity compensation unless disabled.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 20}

    def __init__(
        self,
        control_mode: str = "ee_delta",
        randomization: str | Mapping[str, Any] | None = "default",
        max_episode_steps: int = 50,
        time_step: float = 1.0 / 240.0,
        substeps: int = 12,
        reward: str = "dense",
        reward_weights: Mapping[str, float] | None = None,
        success_height: float = 0.05,
        terminate_on_success: bool = False,
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
        robot_urdf: str = "franka_panda/panda.urdf",
        objects: str | list[str] | Mapping[str, Any] | None = "cube",
    ):
        _check_args(control_mode, render_mode, max_episode_steps, substeps, time_step)
        self.control_mode = control_mode
        self.randomizer = Randomizer(randomization)
        self.objects = ObjectSampler(objects)
        self.task = LiftTask(reward, RewardWeights(**(reward_weights or {})), success_height)
        self.max_episode_steps, self.substeps = int(max_episode_steps), int(substeps)
        self.terminate_on_success = terminate_on_success
        self.ee_step, self.ee_yaw, self.yaw_step = ee_step, ee_yaw, yaw_step
        self.joint_step, self.torque_fraction = joint_step, torque_fraction
        self.gravity_compensation, self.render_mode = gravity_compensation, render_mode
        self.render_size = (render_width, render_height)
        self.camera = (camera_distance, camera_yaw, camera_pitch)
        self.metadata = {**self.metadata, "render_fps": round(1.0 / (time_step * substeps))}

        gui = render_mode == "human"
        self.scene = Scene(time_step=time_step, gui=gui, solver_iterations=solver_iterations)
        self.client = self.scene.client
        self.robot = Panda(self.client, robot_urdf)
        self.robot.reset(NEUTRAL_POSE)
        self._initial_state = self.client.saveState()

        self._build_spaces()
        # Noise applies to what the sensors read, not to the flag and the agent's own action.
        self._sensor_dims = self.obs_slices["grasped"].start

        self._idle_action = np.zeros(self.action_dim, np.float32)
        self._idle_action[-1] = 1.0  # fingers open
        self._steps = 0
        self.episode: dict[str, float] = {}

    def _build_spaces(self) -> None:
        motion_dim = 3 + int(self.ee_yaw) if self.control_mode == "ee_delta" else 7
        self.action_dim = motion_dim + 1
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_dim,), np.float32)
        self.obs_slices, start = {}, 0
        for name, size in _observation_layout(self.action_dim).items():
            self.obs_slices[name] = slice(start, start + size)
            start += size
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (start,), np.float32)

    # --- gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        ep = self.randomizer.sample(rng)
        arm_q = np.add(NEUTRAL_POSE, rng.normal(0.0, ep["arm_pose_noise"], 7))
        self._action_offset = rng.normal(0.0, ep["action_noise_episode"], self.action_dim)
        self._obs_offset = rng.normal(0.0, ep["obs_noise_episode"], self._sensor_dims)
        choice = self.objects.draw(rng)  # last: a cube-only env draws the values it always has
        c = self.client
        self.scene.remove_object()  # the saved state holds no object: restoring needs the same bodies
        c.restoreState(self._initial_state)
        c.setGravity(0, 0, ep["gravity_z"])
        self._place_object(choice, ep)
        self.robot.set_dynamics(ep["joint_damping"], ep["finger_friction"])
        self.robot.reset(np.clip(arm_q, self.robot.lower, self.robot.upper))
        if self.control_mode == "joint_torque":
            self.robot.use_torque_control(ep["finger_force"])
        else:
            self.robot.use_position_control(ep["position_gain_scale"], ep["finger_force"])
            self.robot.command_arm(self.robot.joint_state()[0])
        self.robot.command_fingers(MAX_FINGER_WIDTH)
        if choice.kind in ("mesh", "urdf") and choice.name != "cube":
            self._settle_object()

        self._pending = collections.deque([self._idle_action.copy()] * ep["action_delay"])
        self._prev_action = self._idle_action.copy()
        self._yaw = 0.0
        self._steps = 0
        self.episode = ep
        obs, state = self._observe()
        return obs, self._info(state, success=False)

    def _settle_object(self, max_substeps: int = 48, speed: float = 5e-3) -> None:
        """Let a mesh come to rest and take its height then as its rest height.

        A mesh's bounding box says where its lowest point is, not whether it stands: many
        random_urdfs rock or tip onto a flatter side. Lifting is measured from where it settled.
        """
        c, body = self.client, self.scene.object
        for i in range(max_substeps):
            c.stepSimulation()
            if i >= 8:
                linear, angular = c.getBaseVelocity(body)
                if max(map(abs, linear)) < speed and max(map(abs, angular)) < 10 * speed:
                    break
        self._settle_substeps = i + 1
        self._rest_z = c.getBasePositionAndOrientation(body)[0][2]

    def _place_object(self, choice, ep: dict[str, Any]) -> None:
        """Build the drawn object upright at the drawn pose with the drawn (or its own) dynamics."""
        scale = ep["object_size_scale"] = snap_scale(ep["object_size_scale"])
        geometry = self.objects.geometry(choice)
        self.object_name = f"cube/{scale:.1f}" if choice.name == "cube" else choice.name
        self.object_extents = np.array(geometry.extents, np.float32) * np.float32(scale)
        self._object_offset = np.array(geometry.offset) * scale
        self._rest_z = geometry.rest_height * scale
        self._settle_substeps = 0
        xy = np.add(NOMINAL_OBJECT_XY, (ep["object_x"], ep["object_y"]))
        quat = self.client.getQuaternionFromEuler((0.0, 0.0, ep["object_yaw"]))
        body = self.scene.spawn(choice, scale, [xy[0], xy[1], self._rest_z], quat)
        ranges = self.randomizer.ranges
        if "object_mass" not in ranges:
            ep["object_mass"] = geometry.mass
        if "object_lateral_friction" not in ranges:
            ep["object_lateral_friction"] = geometry.lateral_friction
        self.client.changeDynamics(
            body,
            -1,
            mass=ep["object_mass"],
            lateralFriction=ep["object_lateral_friction"],
            spinningFriction=ep["object_spinning_friction"],
            rollingFriction=ep["object_rolling_friction"],
            restitution=ep["object_restitution"],
        )

    def step(self, action):
        action = np.asarray(action, dtype=np.float32).reshape(self.action_dim)
        if not np.all(np.isfinite(action)):
            raise ValueError(f"action must be finite, got {action.tolist()}")
        action = np.clip(action, -1.0, 1.0)
        # Action delay: the arm executes what the agent chose `action_delay` steps ago.
        self._pending.append(action)
        applied = self._pending.popleft()
        noise = self._action_offset + self.np_random.normal(
            0.0, self.episode["action_noise_step"], self.action_dim
        )
        self._apply(np.clip(applied + noise, -1.0, 1.0))
        self._prev_action = action
        self._steps += 1

        obs, state = self._observe()
        lift = state["object_pos"][2] - self._rest_z
        reward, success = self.task.evaluate(
            state["grasp_pos"], state["object_centre"], lift, state["grasped"]
        )
        terminated = bool(success and self.terminate_on_success)
        truncated = self._steps >= self.max_episode_steps
        return obs, reward, terminated, truncated, self._info(state, success)

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        import pybullet

        width, height = self.render_size
        distance, yaw, pitch = self.camera
        view = self.client.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=[NOMINAL_OBJECT_XY[0] - 0.15, NOMINAL_OBJECT_XY[1], 0.2],
            distance=distance,
            yaw=yaw,
            pitch=pitch,
            roll=0.0,
            upAxisIndex=2,
        )
        projection = self.client.computeProjectionMatrixFOV(60.0, width / height, 0.05, 5.0)
        image = self.client.getCameraImage(
            width, height, view, projection, renderer=pybullet.ER_TINY_RENDERER
        )[2]
        return np.asarray(image, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def close(self):
        if getattr(self, "scene", None) is not None:
            self.scene.close()
            self.scene = None

    # --- internals -----------------------------------------------------------------------------
    def _apply(self, action: np.ndarray) -> None:
        robot = self.robot
        robot.command_fingers((action[-1] + 1.0) / 2.0 * MAX_FINGER_WIDTH)
        if self.control_mode == "joint_torque":
            tau = action[:7] * self.torque_fraction * robot.max_torque
            for _ in range(self.substeps):
                robot.apply_torques(tau + robot.gravity_torques() if self.gravity_compensation else tau)
                self.client.stepSimulation()
            return
        if self.control_mode == "ee_delta":
            grasp_pos, _ = robot.grasp_point()
            target = np.clip(grasp_pos + action[:3] * self.ee_step, WORKSPACE_LOW, WORKSPACE_HIGH)
            if self.ee_yaw:
                self._yaw = float(np.clip(self._yaw + action[3] * self.yaw_step, -math.pi / 2, math.pi / 2))
                q_target = robot.inverse_kinematics(
                    target, self.client.getQuaternionFromEuler((math.pi, 0.0, self._yaw))
                )
            else:
                q_target = robot.inverse_kinematics(target)
        else:
            q, _, _ = robot.joint_state()
            q_target = np.clip(q + action[:7] * self.joint_step, robot.lower, robot.upper)
        robot.command_arm(q_target)
        for _ in range(self.substeps):
            self.client.stepSimulation()

    def _observe(self) -> tuple[np.ndarray, dict[str, Any]]:
        c, robot, body = self.client, self.robot, self.scene.object
        q, qd, width = robot.joint_state()
        grasp_pos, grasp_vel = robot.grasp_point()
        object_pos, object_quat = c.getBasePositionAndOrientation(body)
        object_linvel, object_angvel = c.getBaseVelocity(body)
        object_pos = np.array(object_pos)
        centre = object_pos
        if self._object_offset.any():
            rotation = np.array(c.getMatrixFromQuaternion(object_quat)).reshape(3, 3)
            centre = object_pos + rotation @ self._object_offset
        grasped = LiftTask.grasped(c, robot.body, robot.finger_links, body)
        obs = np.concatenate(
            [
                q,
                qd,
                [width],
                grasp_pos,
                grasp_vel,
                object_pos,
                object_quat,
                object_linvel,
                object_angvel,
                centre - grasp_pos,
                self.object_extents,
                [float(grasped)],
                self._prev_action,
            ]
        ).astype(np.float32)
        ep = self.episode
        if ep["obs_noise_step"] > 0 or ep["obs_noise_episode"] > 0:
            noise = self._obs_offset + self.np_random.normal(0.0, ep["obs_noise_step"], self._sensor_dims)
            obs[: self._sensor_dims] += noise.astype(np.float32)
        state = {
            "grasp_pos": grasp_pos,
            "object_pos": object_pos,
            "object_centre": centre,
            "object_quat": object_quat,
            "grasped": grasped,
        }
        return obs, state

    def _info(self, state: dict[str, Any], success: bool) -> dict[str, Any]:
        # numpy scalars, not Python ones: TorchRL's info reader needs a dtype.
        return {
            "is_success": np.bool_(success),
            "grasped": np.bool_(state["grasped"]),
            "lift_height": np.float32(state["object_pos"][2] - self._rest_z),
            "object": self.object_name,
            "object_extents": self.object_extents.copy(),
            "object_tilt": np.float32(tilt(state["object_quat"])),
            "randomization": dict(self.episode),
        }
