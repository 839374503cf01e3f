"""Stable-Baselines3's gradient step on rlgrasp's shapes: the peer ``bench_update.py --peer sb3`` times
beside rlgrasp's SAC (or TQC) step, in the same process, so that the ratio of the two is fair on a
machine whose load changes from one run to the next.

The SB3 learner (SAC; sb3-contrib's TQC for ``algo=tqc``) gets the keywords ``bench_peer.sb3_kwargs``
maps from the same composed config (hidden sizes, critics, quantiles, batch size, gamma, tau), on an
env that only declares rlgrasp's observation and action sizes: ``train`` never steps it. Its replay
buffer is filled with as many random transitions as rlgrasp's holds. What SB3 cannot replay
(demonstrations, HER's relabelling) is left out: its step then samples its plain buffer.
"""

from __future__ import annotations

import copy
import time
from typing import Any

import numpy as np
from bench_peer import sb3_class, sb3_kwargs


def peer_model(cfg: Any, obs_dim: int, act_dim: int, frames: int) -> Any:
    """SB3's learner for ``cfg`` (``sb3_class``), its buffer holding ``frames`` random transitions."""
    import gymnasium as gym
    from stable_baselines3.common.logger import configure

    plain = copy.deepcopy(cfg)
    plain.algo.demos = None  # SB3 replays no demonstrations: its step samples online data only
    if plain.algo.get("her") is not None:
        plain.algo.her.enabled = False  # relabelling is the buffer's, not the step's
    kwargs = {**sb3_kwargs(plain), "buffer_size": frames, "learning_starts": 0}

    class Shapes(gym.Env):
        """Only the spaces: ``train`` reads the replay buffer, never the env."""

        observation_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (act_dim,), np.float32)

    model = sb3_class(cfg)("MlpPolicy", Shapes(), seed=0, device="cpu", verbose=0, **kwargs)
    model.set_logger(configure(None, []))  # train() records its losses; nowhere to write them
    fill(model.replay_buffer, frames, np.random.default_rng(0))
    return model


def fill(buffer: Any, frames: int, rng: np.random.Generator) -> None:
    """``frames`` random transitions written straight into SB3's ``ReplayBuffer`` arrays (one env)."""
    for name in ("observations", "next_observations", "actions", "rewards"):
        array = getattr(buffer, name)
        array[:frames] = rng.uniform(-1, 1, array[:frames].shape).astype(array.dtype)
    buffer.dones[:frames] = 0
    buffer.pos, buffer.full = frames % buffer.buffer_size, frames >= buffer.buffer_size


def peer_step_ms(model: Any, steps: int, batch_size: int) -> float:
    """ms per gradient step of SB3's ``train`` over ``steps`` steps in one call (as its learn loop
    makes it), after a warm-up call of a few steps."""
    model.train(gradient_steps=3, batch_size=batch_size)  # the optimizers' state, the allocator
    t0 = time.perf_counter()
    model.train(gradient_steps=steps, batch_size=batch_size)
    return (time.perf_counter() - t0) / steps * 1000
