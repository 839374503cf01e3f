"""The collectors' schema (``collector=process|single|ray``), apart from their code so that the config
module, at the bottom of the layers, imports no collector: rlgrasp.train.collection.collectors builds
from it."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class CollectorConfig:
    """How frames are collected: ``_target_`` is the backend, a class of
    ``rlgrasp.train.collection.collectors`` built from the other keys (``collector=process``:
    TorchRL's collector over worker processes; ``single``: in-process; ``ray``: collector actors on a
    Ray cluster). Each worker steps one gymnasium ``SyncVectorEnv`` of ``envs_per_worker`` envs and
    runs the actor on the whole batch; frames per batch = workers x envs_per_worker x steps_per_env."""

    _target_: str = "rlgrasp.train.collection.collectors.ProcessCollector"
    num_workers: int = 2  # 0: in-process
    envs_per_worker: int = 4
    steps_per_env: int = 128
    torch_threads: int = 1
    # Collect the next batch while the learner updates (one update of lag;
    # rlgrasp/train/collection/batches.py, ppo.py).
    overlap: bool = True
    # Cut each env's first episode at a different length so that a worker's envs are not in phase:
    # needed when steps_per_env is short against an episode (rlgrasp/train/collection/collect.py
    # StaggeredStart).
    stagger_starts: bool = False
    # A batch not delivered within this many seconds ends the run (a worker that hangs, not dies: a
    # checkpoint is saved and the run stops in one line, instead of waiting for ever).
    worker_timeout_s: float = 600.0


@dataclass
class RayConfig:
    """Where ``collector=ray`` runs its collector actors (one per worker)."""

    # null: start a private local Ray bound to node_ip_address; "auto" or "host:6379": join a cluster.
    address: str | None = None
    # Local Ray only: stay on loopback unless told otherwise (set the node's address to go multi-machine).
    node_ip_address: str = "127.0.0.1"
    num_cpus: int | None = None  # local Ray only (null: all cores)
    cpus_per_worker: float = 1.0  # Ray resources each collector actor reserves
    memory_per_worker_gb: float = 1.0
    include_dashboard: bool = False


@dataclass
class RayCollectorConfig(CollectorConfig):
    """``collector=ray``: the process backend's keys plus where Ray runs (``collector.ray.*``)."""

    _target_: str = "rlgrasp.train.collection.collectors.RayCollector"
    ray: RayConfig = field(default_factory=RayConfig)
