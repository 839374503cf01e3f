"""Any registered gymnasium env as the trainer's target (``env=gym env.id=...``), goal-conditioned ones
included, so that rlgrasp's learners can be judged on tasks no one here wrote.

``make_gym_env`` is the ``_target_`` of ``configs/env/gym.yaml``: ``gymnasium.make(id, ...)`` behind
``GymEnv``, which adapts the env to what the training core reads from one and to nothing more:

- **one float32 vector** (``observation=flat``, the default): the collector reads ``observation``
  as one vector and the learners' networks take one. A goal env's Dict (panda-gym's, gymnasium-robotics'
  ``observation`` / ``achieved_goal`` / ``desired_goal``) is flattened with the goals last, as
  rlgrasp's own goal tasks do (``env.task.observation=flat``), and ``obs_slices`` says where each
  key lies: HER rewrites the desired goal there and reads the achieved one (``rlgrasp.algos.sac.her``).
  ``observation=dict`` keeps the env's own Dict, for goal tools that read one (Stable-Baselines3's
  HER in ``benchmarks/bench_peer.py``); the trainer refuses it in one line.
- **``compute_reward``** of the env itself, reached through gymnasium's wrappers: HER relabels with
  the env's own rule and scale (panda-gym pays -1 / 0 where rlgrasp's tasks pay 0 / 1).
- **``info`` keeps ``is_success`` only**, as a bool: it is the one entry the trainer reads
  (``rlgrasp.train.collection.collect.INFO_DTYPES``: the success rate), a vector env stacks every
  entry of every env's info each step, and another env's entry could carry a name rlgrasp reads with
  its own meaning.
- **``max_episode_steps``** as an attribute: the collector's staggered starts and the periodic
  evaluation read an episode's length from the env (``gymnasium.make``'s ``TimeLimit`` ends them).

An id another package registers names that package first, gymnasium's ``module:id``
(``panda_gym:PandaReach-v3``): gymnasium imports the module before it looks the id up, in every
collector worker too, where nothing imported it before. Bad input is refused in one line naming its
key by ``check_config`` (rlgrasp.train.validate.validate_train), before any worker starts.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from rlgrasp.errors import ConfigError

#: The ``_target_`` a config and a checkpoint name this factory by (``rlgrasp.received.PARTS["env"]``).
TARGET = "rlgrasp.envs.gym_env.make_gym_env"
#: ``env.observation``'s values: ``flat`` for the trainer, ``dict`` for goal tools.
OBSERVATIONS = ("flat", "dict")
#: A goal env's Dict keys (gymnasium-robotics' ``GoalEnv``; panda-gym's), the goals last when flat.
GOALS = ("achieved_goal", "desired_goal")
#: The packages of envs rlgrasp's extras install, and the line that installs each.
EXTRAS = {"panda_gym": 'pip install -e ".[panda]"'}


def make_gym_env(
    id: str,  # gymnasium's own name for it (and the config's key)
    observation: str = "flat",
    max_episode_steps: int | None = None,
    **kwargs: Any,
) -> GymEnv:
    """``gymnasium.make(id, max_episode_steps, **kwargs)`` adapted for the trainer (``GymEnv``).

    ``id``: a registered id, ``module:id`` when another package registers it (the module is imported
    first, as ``gymnasium.make`` does); ``observation``: ``flat`` (one vector, the goals last) or
    ``dict`` (the env's own); ``max_episode_steps``: null keeps the registration's limit; ``kwargs``:
    the env's own keywords (``env.reward_type=dense`` for panda-gym's)."""
    name = registered_id(id)
    if observation not in OBSERVATIONS:
        raise ConfigError(f"env.observation={observation!r}: must be {' or '.join(OBSERVATIONS)}")
    try:
        env = gym.make(name, max_episode_steps=max_episode_steps, **kwargs)
    except TypeError as exc:  # a keyword the env's constructor does not take
        reason = str(exc).splitlines()[0]
        raise ConfigError(f"env.id={id!r}: {reason} (env.<key>: the env's own keywords)") from None
    try:
        return GymEnv(env, id, flat=observation == "flat")
    except ConfigError:  # actions or observations the learners cannot read: its simulator closed
        env.close()
        raise


def registered_id(env_id: Any) -> str:
    """The id to look up once ``env_id``'s module is imported; ``ConfigError`` naming ``env.id`` for an
    id that is not a string, a module that cannot be imported, or an id nothing registered."""
    if not isinstance(env_id, str) or not env_id.strip(":"):
        raise ConfigError(f"env.id={env_id!r}: must be a gymnasium id, e.g. env.id=panda_gym:PandaReach-v3")
    module, _, name = env_id.rpartition(":")
    if module:
        _import(module, env_id)
    if name not in gym.registry:
        raise ConfigError(f"env.id={env_id!r}: no gymnasium env {name!r} is registered{_near(name, module)}")
    _check_importer(env_id, module, gym.registry[name])
    return name


def _import(module: str, env_id: str) -> None:
    """Import the module an id names (it registers its envs), or one line naming what is missing."""
    try:
        importlib.import_module(module)
    except ModuleNotFoundError as exc:
        missing = (exc.name or module).split(".")[0]
        hint = EXTRAS.get(missing, f"pip install the package that provides {missing}")
        raise ConfigError(f"env.id={env_id!r}: the module {missing} is not installed ({hint})") from None
    except Exception as exc:  # noqa: BLE001 - whatever the module raised while importing
        reason = str(exc).splitlines()[0] if str(exc) else ""
        raise ConfigError(
            f"env.id={env_id!r}: importing {module} failed: {type(exc).__name__}: {reason}"
        ) from None


def _near(name: str, module: str) -> str:
    """The registered ids that look like ``name``, and how to name another package's."""
    close = difflib.get_close_matches(name, list(gym.registry), n=3)
    near = f" (registered ids that look alike: {', '.join(close)})" if close else ""
    how = "" if module else "; an id another package registers names it first, e.g. panda_gym:PandaReach-v3"
    return near + how


def _check_importer(env_id: str, module: str, spec: gym.envs.registration.EnvSpec) -> None:
    """Refuse an id without its module that a package other than gymnasium registered: it resolves
    here only because something imported that package, and a collector worker imports nothing."""
    entry = spec.entry_point
    where = entry.split(":")[0] if isinstance(entry, str) else getattr(entry, "__module__", "")
    top = where.split(".")[0]
    if module or top in ("", "gymnasium"):
        return
    raise ConfigError(
        f"env.id={env_id!r}: {top} registers it, and a collector worker imports nothing: "
        f"name the module first, env.id={top}:{env_id}"
    )


def registered_steps(env_id: str) -> int | None:
    """The episode length ``env_id``'s registration gives (``TimeLimit``'s), None for none."""
    return gym.registry[registered_id(env_id)].max_episode_steps


class GymEnv(gym.Env):
    """A gymnasium env as the trainer reads one (the module docstring says why each change is made):
    a flat float32 observation with ``obs_slices`` (or the env's Dict), ``info`` of ``is_success``
    alone, the env's own ``compute_reward``, ``max_episode_steps``. ``env.unwrapped`` is this adapter,
    where the training core looks for those attributes."""

    #: The key that chooses the observation (the trainer's refusal of a Dict names it).
    observation_key = "env.observation"

    def __init__(self, env: gym.Env, env_id: str, flat: bool = True) -> None:
        self.env, self.env_id, self.flat = env, env_id, flat
        _check_actions(env.action_space, env_id)
        self.action_space = env.action_space
        self.keys = _observation_keys(env.observation_space, env_id)  # None: a Box
        self.obs_slices = _slices(env.observation_space, self.keys)
        space = env.observation_space
        self.observation_space = _flat_space(space, self.keys) if flat else space
        self.max_episode_steps = env.spec.max_episode_steps if env.spec is not None else None
        self.metadata = env.metadata
        self.render_mode = env.render_mode

    @property
    def goal_env(self) -> bool:
        """Whether HER can relabel this env: a Dict with both goals and the env's ``compute_reward``."""
        return self.keys is not None and all(g in self.keys for g in GOALS) and self._reward_fn() is not None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        obs, info = self.env.reset(seed=seed, options=options)
        return self._observe(obs), _success_only(info)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._observe(obs), float(reward), bool(terminated), bool(truncated), _success_only(info)

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        """The env's own ``compute_reward`` (vectorized over leading axes in goal envs)."""
        reward_fn = self._reward_fn()
        if reward_fn is None:
            raise AttributeError(f"{self.env_id} has no compute_reward")
        return reward_fn(achieved_goal, desired_goal, info)

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()

    def _reward_fn(self) -> Any:
        return getattr(self.env.unwrapped, "compute_reward", None)

    def _observe(self, obs: Any) -> Any:
        if not self.flat:
            return obs
        if self.keys is None:
            return np.asarray(obs, dtype=np.float32).reshape(-1)
        return np.concatenate([np.asarray(obs[k], dtype=np.float32).reshape(-1) for k in self.keys])


def _success_only(info: Mapping[str, Any]) -> dict[str, bool]:
    return {"is_success": bool(info["is_success"])} if "is_success" in info else {}


def _check_actions(space: gym.Space, env_id: str) -> None:
    if not isinstance(space, gym.spaces.Box):
        raise ConfigError(
            f"env.id={env_id!r}: its actions are a {type(space).__name__}; rlgrasp's learners act in a Box"
        )


def _observation_keys(space: gym.Space, env_id: str) -> list[str] | None:
    """A Dict's keys in the flat vector's order (the goals last), None for a Box; one line for another
    space, or a Dict holding something else than Boxes."""
    if isinstance(space, gym.spaces.Box):
        return None
    if isinstance(space, gym.spaces.Dict) and all(isinstance(s, gym.spaces.Box) for s in space.values()):
        keys = list(space.keys())
        return [k for k in keys if k not in GOALS] + [g for g in GOALS if g in keys]
    raise ConfigError(
        f"env.id={env_id!r}: it observes a {space}; rlgrasp's learners read a Box or a Dict of Boxes"
    )


def _slices(space: gym.Space, keys: list[str] | None) -> dict[str, slice]:
    """Where each key lies in the flat vector (``observation`` for a Box's whole)."""
    if keys is None:
        return {"observation": slice(0, int(np.prod(space.shape)))}
    slices, start = {}, 0
    for key in keys:
        size = int(np.prod(space[key].shape))
        slices[key], start = slice(start, start + size), start + size
    return slices


def _flat_space(space: gym.Space, keys: list[str] | None) -> gym.spaces.Box:
    parts = [space] if keys is None else [space[k] for k in keys]
    low = np.concatenate([np.asarray(p.low, np.float32).reshape(-1) for p in parts])
    high = np.concatenate([np.asarray(p.high, np.float32).reshape(-1) for p in parts])
    return gym.spaces.Box(low, high, dtype=np.float32)


def check_config(env_cfg: Mapping[str, Any], her: bool) -> None:
    """``env=gym``'s bad input in one line naming its key, before any worker starts: a missing or unknown
    id, a module that is not installed, a bad ``observation`` or ``max_episode_steps``, keywords the env
    does not take, an env that does not act in a Box, and, with ``her``, an env without goals."""
    if env_cfg.get("id") in (None, "???"):
        raise ConfigError("env.id: required with env=gym, a gymnasium id (env.id=panda_gym:PandaReach-v3)")
    steps = env_cfg.get("max_episode_steps")
    if steps is not None and (not isinstance(steps, int) or steps < 1):
        raise ConfigError(f"env.max_episode_steps={steps!r}: must be >= 1, or null (the registration's)")
    keywords = {k: v for k, v in env_cfg.items() if k != "_target_"}
    env = make_gym_env(**keywords)
    try:
        if her and not env.goal_env:
            raise ConfigError(
                f"algo.her.enabled=true: env.id={env_cfg['id']!r} {_no_goals(env)}; HER relabels a goal "
                f"env's ({' and '.join(GOALS)} in a Dict, and its compute_reward: panda-gym's, for one)"
            )
    finally:
        env.close()


def _no_goals(env: GymEnv) -> str:
    if env.keys is None:
        return "observes a Box, without goals"
    if not all(g in env.keys for g in GOALS):
        return f"observes a Dict of {', '.join(env.keys)}, without {' and '.join(GOALS)}"
    return "has no compute_reward"
