"""What a training run is made of, built from its config in one place: the env factory, the env's
spec, the actor and critic, the collector backend and the batches it gives. Training, the benchmark
scripts and the tests all build them here."""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torchrl.collectors import BaseCollector

from rlgrasp.envs.factory import env_factory
from rlgrasp.models.cnn import actor_norm, build_vision_actor
from rlgrasp.models.mlp import OBS_KEY, RunningNorm, build_critic, build_models
from rlgrasp.models.spec import PRIVILEGED_KEY, env_spec, vision_spec
from rlgrasp.train.collection.batches import Batches
from rlgrasp.train.collection.collect import EnvFactory
from rlgrasp.train.collection.collectors import CollectorBackend, collector_backend, shut_down
from rlgrasp.train.tracking.metrics import Phases


@dataclass
class Parts:
    cfg: Any
    make_env: EnvFactory
    spec: dict[str, Any]
    actor: torch.nn.Module
    critic: torch.nn.Module
    norm: RunningNorm  # the actor's state normalizer
    collector: CollectorBackend
    #: Each normalizer and the batch entry it learns from (the learner updates them all).
    norms: dict[str, RunningNorm] = field(default_factory=dict)

    @property
    def frames_per_batch(self) -> int:
        return self.collector.frames_per_batch

    @property
    def kind(self) -> str:
        """``vision`` for a camera policy (how checkpoints say to rebuild it), else ``state``."""
        return "vision" if self.spec.get("images") else "state"

    def make_collector(
        self, generation: int = 0, error_dir: str | None = None, policy: torch.nn.Module | None = None
    ) -> BaseCollector:
        """The configured collector running ``policy`` (default ``actor``); ``generation`` shifts
        the seeds on resume."""
        return self.collector.build(self.make_env, policy or self.actor, self.cfg.seed, generation, error_dir)

    @contextlib.contextmanager
    def open_batches(
        self, learner: torch.nn.Module, generation: int, error_dir: Path, env_sync: Any, phases: Phases
    ) -> Iterator[Batches]:
        """The collector's batches (``rlgrasp.train.collection.batches``), run by a copy of ``learner`` that
        takes its weights between batches; the workers are shut down however the loop ends."""
        behaviour = copy.deepcopy(learner)
        with phases("first batch"):  # the workers' start-up: spawned, imports, envs built
            collector = self.make_collector(generation, str(error_dir), behaviour)
        backend = self.collector
        timeout_s = None if backend.in_process else backend.worker_timeout_s
        batches = Batches(collector, learner, behaviour, backend.collects_ahead, env_sync, timeout_s)
        try:
            yield batches
        finally:
            with phases("shutdown"):
                batches.close()
                shut_down(collector)


def build_parts(cfg: Any, device: torch.device | str = "cpu") -> Parts:
    """Env factory and spec, then the models (their init draws from torch's global RNG: seed first)."""
    make_env = env_factory(cfg.env)
    collector = collector_backend(cfg.collector)
    camera = bool(cfg.env.get("camera"))
    spec = vision_spec(make_env) if camera else env_spec(make_env)
    if camera:
        actor, critic, norms = _camera_models(spec, cfg.model)
    else:
        actor, critic, norm = build_models(
            spec["obs_dim"], torch.tensor(spec["action_low"]), torch.tensor(spec["action_high"]), cfg.model
        )
        norms = {OBS_KEY: norm}
    return Parts(cfg, make_env, spec, actor.to(device), critic.to(device), norms[OBS_KEY], collector, norms)


def _camera_models(spec: dict[str, Any], model_cfg: Any) -> tuple[Any, Any, dict[str, RunningNorm]]:
    """The camera actor (proprioception + images) and an MLP critic on the privileged state, each
    with its own normalizer: the critic is never deployed, so it may read what no robot senses
    (Pinto et al. 2018), which gives the advantages a value that does not have to be seen."""
    actor = build_vision_actor(spec, model_cfg)
    critic_norm = RunningNorm(spec["privileged_dim"], clip=model_cfg.obs_clip, enabled=model_cfg.obs_norm)
    critic = build_critic(critic_norm, spec["privileged_dim"], model_cfg, in_key=PRIVILEGED_KEY)
    return actor, critic, {OBS_KEY: actor_norm(actor), PRIVILEGED_KEY: critic_norm}
