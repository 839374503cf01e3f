"""The collector backends: where the workers that step the envs run.

``collector._target_`` names one of these classes and Hydra builds it from the other ``collector.*``
keys (``configs/collector/<name>.yaml``); ``build`` then makes TorchRL's synchronous collector over
the workers. A new backend is a subclass here (or anywhere importable) plus a YAML file naming it.
Every backend gives worker ``w`` the same envs (``worker_seed``) and the same batch, so a seed gives
one run whichever backend collects it.
"""

from __future__ import annotations

import functools
import logging
import multiprocessing
import os
from collections.abc import Mapping
from typing import Any

import torch
from hydra.utils import instantiate
from torchrl.collectors import BaseCollector, Collector

from rlgrasp.collector_schema import CollectorConfig, RayCollectorConfig, RayConfig  # noqa: F401
from rlgrasp.train.collection.collect import EnvFactory, make_batched_env, worker_seed
from rlgrasp.utils import guard_spawned_children

log = logging.getLogger("rlgrasp.train")


class CollectorBackend:
    """``num_workers`` workers (0: in-process), each stepping ``envs_per_worker`` envs for
    ``steps_per_env`` steps per batch; the keys of ``rlgrasp.collector_schema.CollectorConfig``."""

    def __init__(
        self,
        num_workers: int = 2,
        envs_per_worker: int = 4,
        steps_per_env: int = 128,
        torch_threads: int = 1,
        overlap: bool = True,
        stagger_starts: bool = False,
        worker_timeout_s: float = 600.0,
    ) -> None:
        self.num_workers = num_workers
        self.envs_per_worker = envs_per_worker
        self.steps_per_env = steps_per_env
        self.torch_threads = torch_threads
        self.overlap = overlap
        self.stagger_starts = stagger_starts
        self.worker_timeout_s = worker_timeout_s

    @property
    def in_process(self) -> bool:
        return self.num_workers == 0

    @property
    def frames_per_batch(self) -> int:
        workers = 1 if self.in_process else self.num_workers
        return workers * self.envs_per_worker * self.steps_per_env

    @property
    def collects_ahead(self) -> bool:
        """Whether batches come one update late (``overlap``; an in-process collector cannot)."""
        return self.overlap and not self.in_process

    def build(
        self,
        make_env: EnvFactory,
        policy: torch.nn.Module,
        seed: int,
        generation: int = 0,
        error_dir: str | None = None,
    ) -> BaseCollector:
        """TorchRL's collector running ``policy`` in the workers; ``generation`` shifts the seeds on
        resume; a failing env leaves its report in ``error_dir``."""
        common = {
            "frames_per_batch": self.frames_per_batch,
            "total_frames": -1,
            "auto_register_policy_transforms": False,
        }
        if self.in_process:
            env = make_batched_env(
                make_env,
                self.envs_per_worker,
                worker_seed(seed, 0, generation),
                0,
                torch.get_num_threads(),
                error_dir,
                stagger=self.stagger_starts,
            )
            return Collector(env, policy, **common)
        workers = [
            functools.partial(
                make_batched_env,
                make_env,
                self.envs_per_worker,
                worker_seed(seed, w, generation),
                w,
                self.torch_threads,
                error_dir,
                stagger=self.stagger_starts,
            )
            for w in range(self.num_workers)
        ]
        return self.across_workers(workers, policy, common)

    def across_workers(self, workers: list, policy: torch.nn.Module, common: dict[str, Any]) -> BaseCollector:
        """The collector over ``workers`` (each builds one worker's envs); the backend's own part."""
        raise NotImplementedError


class ProcessCollector(CollectorBackend):
    """``collector=process``: one spawned process per worker on this machine."""

    def across_workers(self, workers: list, policy: torch.nn.Module, common: dict[str, Any]) -> BaseCollector:
        # Inside a joblib (loky) multirun job the start method is not spawn; the workers need it: a
        # forked child would inherit the parent's PyBullet and torch thread state.
        multiprocessing.set_start_method("spawn", force=True)
        guard_spawned_children()  # the workers end with this process, even mid-import (rlgrasp.utils)
        # num_threads: TorchRL would set this process's torch threads to the cores left after one a
        # worker (with 2 workers on 2 cores: one), and the learner's updates would run on one thread
        # whatever algo.learner_threads says; the learner's own count is kept instead.
        return Collector(
            workers,
            policy,
            num_collectors=self.num_workers,
            sync=True,
            backend="process",
            num_threads=torch.get_num_threads(),
            **common,
        )


class SingleCollector(CollectorBackend):
    """``collector=single``: the envs step in the learner's process (debuggers, profilers)."""

    @property
    def in_process(self) -> bool:
        return True


class RayCollector(CollectorBackend):
    """``collector=ray``: one TorchRL ``Collector`` actor per worker, placed by Ray (across the nodes
    of a cluster); a Ray already initialised is reused."""

    def __init__(self, ray: Mapping[str, Any] | None = None, **keys: Any) -> None:
        super().__init__(**keys)
        self.ray = RayConfig(**(ray or {}))

    def across_workers(self, workers: list, policy: torch.nn.Module, common: dict[str, Any]) -> BaseCollector:
        remote = {
            "num_cpus": self.ray.cpus_per_worker,
            "memory": int(self.ray.memory_per_worker_gb * 1024**3),
        }
        common = dict(common)
        inner = {"auto_register_policy_transforms": common.pop("auto_register_policy_transforms")}
        common["total_frames"] = 2**62  # RayCollector stops at once on -1 (endless elsewhere)
        collector = Collector(
            workers,
            policy,
            num_collectors=self.num_workers,
            sync=True,
            backend="ray",
            ray_init_config=ray_init_kwargs(self.ray),
            remote_configs=remote,
            collector_kwargs=[dict(inner) for _ in workers],
            **common,
        )
        collector.update_policy_weights_()  # initialise the weight sync before the first batch
        return collector


def ray_init_kwargs(ray_cfg: RayConfig) -> dict[str, Any]:
    """``ray.init`` keywords: join ``address`` if set, else a private local Ray on ``node_ip_address``.

    A local Ray binds to the machine's network address unless it is given one.
    """
    if ray_cfg.address:
        return {"address": ray_cfg.address, "ignore_reinit_error": True, "log_to_driver": False}
    os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    return {
        "num_cpus": ray_cfg.num_cpus,
        "_node_ip_address": ray_cfg.node_ip_address,
        "include_dashboard": ray_cfg.include_dashboard,
        "ignore_reinit_error": True,
        "log_to_driver": False,
    }


def collector_backend(node: Any) -> CollectorBackend:
    """The backend a ``collector`` config node names, with plain Python values."""
    return instantiate(node, _convert_="all")


def begin_shutdown(collector: BaseCollector) -> None:
    """Ask idle process workers to end, without waiting for them (``shut_down`` waits): the learner
    does its last work (the final evaluation) while they close their envs and exit. Nothing for a
    collector without process workers."""
    procs, pipes = getattr(collector, "procs", None), getattr(collector, "pipes", None)
    if not procs or not pipes:
        return
    for proc, pipe in zip(procs, pipes):
        try:
            if proc.is_alive():
                pipe.send((None, "close"))  # TorchRL's own message (its ``shutdown`` sends the same)
        except (EOFError, OSError, ValueError):
            pass


def shut_down(collector: BaseCollector) -> None:
    """Stop the workers, then the weight-sync schemes: left to ``__del__`` at interpreter exit, a
    scheme's shutdown starts a queue feeder thread during finalization and the process never ends."""
    try:
        collector.shutdown()
    except Exception as exc:  # noqa: BLE001 - a dead worker can make shutdown complain
        log.warning("collector shutdown: %s", exc)
    for scheme in (getattr(collector, "_weight_sync_schemes", None) or {}).values():
        try:
            scheme.shutdown()
        except Exception as exc:  # noqa: BLE001
            log.warning("weight sync shutdown: %s", exc)
