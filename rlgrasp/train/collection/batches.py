"""The learner's batches, and the moment the workers get new weights.

The workers run a copy of the actor (``behaviour``). TorchRL shares a CPU policy's parameters with
its process workers, so without the copy every optimizer step would reach a rollout in flight and
one seed could give two different runs. The copy takes the learner's weights only while the workers
are idle, between two batches.

With ``overlap`` the next batch is requested before the learner trains on this one, so the workers
collect while the learner updates and evaluates (otherwise a 1-thread learner leaves the other cores
idle for the whole update). That batch is collected with the weights of one update before, so the
learner recomputes its log-probs with its own weights before the epochs (``PPOLearner``,
``stale_batches``). TorchRL's asynchronous collector overlaps too, but each worker's batch then
carries whatever weights it had when it started, which depends on timing.

An ``env_sync`` (ADR's ``rlgrasp.train.collection.adr_sync.AdrSync``) reads each batch as it arrives
and pushes what the envs need at the same idle moment as the weights, so the next batch already uses
it.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any, Protocol

import torch
from tensordict import TensorDictBase
from torchrl.collectors import BaseCollector

#: Waited for an in-flight batch when the run stops before the collector shuts down; a healthy
#: batch takes about a second, a worker that died makes the collector raise well before this.
DRAIN_TIMEOUT_S = 120.0


class EnvSync(Protocol):
    def observe(self, batch: TensorDictBase) -> Any: ...

    def push(self, collector: BaseCollector) -> None: ...


class WorkerTimeoutError(RuntimeError):
    """No batch arrived within ``collector.worker_timeout_s``: a worker hangs."""


class Batches(Iterator[TensorDictBase]):
    """``next()`` gives the next batch; with ``overlap`` the one after is already being collected.
    ``timeout_s``: how long a batch may take before ``WorkerTimeoutError`` (a worker that hangs,
    not dies, would otherwise keep the learner waiting for ever; None: no limit)."""

    def __init__(
        self,
        collector: BaseCollector,
        actor: torch.nn.Module,
        behaviour: torch.nn.Module,
        overlap: bool,
        env_sync: EnvSync | None = None,
        timeout_s: float | None = None,
    ) -> None:
        self.collector, self.actor, self.behaviour, self.overlap = collector, actor, behaviour, overlap
        self.env_sync, self.timeout_s = env_sync, timeout_s
        self.timed_out = False
        #: False before the last batch of a run: nothing is collected after it (it would be dropped).
        self.ahead = True
        self._iterator = iter(collector)
        self._thread: threading.Thread | None = None
        self._result: tuple[Any, BaseException | None] = (None, None)

    def __next__(self) -> TensorDictBase:
        if not self.overlap:
            self._push_weights()
            if self.timeout_s is None:
                return self._arrived(next(self._iterator))
            self._start()  # through the fetching thread only to bound the wait
            return self._arrived(self._wait())
        if self._thread is None:
            if self.env_sync is not None:  # the first batch too (a resume's ranges are not the start's)
                self.env_sync.push(self.collector)
            self._start()
        batch = self._arrived(self._wait())
        self._push_weights()
        if self.ahead:
            self._start()
        return batch

    def _arrived(self, batch: TensorDictBase) -> TensorDictBase:
        if self.env_sync is not None:
            self.env_sync.observe(batch)
        return batch

    def close(self) -> None:
        """Let a batch in flight arrive (it is dropped) so the workers are idle at shutdown."""
        if self._thread is not None and not self.timed_out:
            self._thread.join(DRAIN_TIMEOUT_S)
        self._thread = None

    def _push_weights(self) -> None:
        self.behaviour.load_state_dict(self.actor.state_dict())  # in place, into the shared memory
        self.collector.update_policy_weights_()
        if self.env_sync is not None:
            self.env_sync.push(self.collector)

    def _start(self) -> None:
        def fetch() -> None:
            try:
                self._result = (next(self._iterator), None)
            except BaseException as exc:  # noqa: BLE001 - re-raised in the learner's thread
                self._result = (None, exc)

        self._result = (None, None)
        # A daemon thread: a collector that never answers must not keep the process alive.
        self._thread = threading.Thread(target=fetch, name="rlgrasp-collect", daemon=True)
        self._thread.start()

    def _wait(self) -> TensorDictBase:
        assert self._thread is not None
        self._thread.join(self.timeout_s)
        if self._thread.is_alive():  # the daemon thread is left behind; the run stops
            self.timed_out = True
            raise WorkerTimeoutError(
                f"no batch from the workers in {self.timeout_s:g} s: a worker hangs "
                "(collector.worker_timeout_s sets how long a batch may take)"
            )
        self._thread = None
        batch, error = self._result
        if error is not None:
            raise error
        return batch
