"""What a training run is made of, built from its config in one place: the env factory, the env's
spec, the actor and critic, and the collector backend. Training, the benchmark scripts and the tests
all build them here."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torchrl.collectors import BaseCollector

from rlgrasp.envs.factory import env_factory
from rlgrasp.train.collect import EnvFactory, env_spec
from rlgrasp.train.collectors import CollectorBackend, collector_backend
from rlgrasp.train.models import RunningNorm, build_models


@dataclass
class Parts:
    cfg: Any
    make_env: EnvFactory
    spec: dict[str, Any]
    actor: torch.nn.Module
    critic: torch.nn.Module
    norm: RunningNorm
    collector: CollectorBackend

    @property
    def frames_per_batch(self) -> int:
        return self.collector.frames_per_batch

    def make_collector(
        self, generation: int = 0, error_dir: str | None = None, policy: torch.nn.Module | None = None
    ) -> BaseCollector:
        """The configured collector running ``policy`` (default ``actor``); ``generation`` shifts
        the seeds on resume."""
        return self.collector.build(self.make_env, policy or self.actor, self.cfg.seed, generation, error_dir)


def build_parts(cfg: Any, device: torch.device | str = "cpu") -> Parts:
    """Env factory and spec, then the models (their init draws from torch's global RNG: seed first)."""
    make_env = env_factory(cfg.env)
    spec = env_spec(make_env)
    actor, critic, norm = build_models(
        spec["obs_dim"], torch.tensor(spec["action_low"]), torch.tensor(spec["action_high"]), cfg.model
    )
    collector = collector_backend(cfg.collector)
    return Parts(cfg, make_env, spec, actor.to(device), critic.to(device), norm, collector)
