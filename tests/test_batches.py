"""When the workers see new weights: only between batches, one update late with overlap."""

from __future__ import annotations

import threading
import time

import pytest
import torch

from rlgrasp.train.collection.batches import Batches, WorkerTimeoutError


class RecordingCollector:
    """Stands in for a TorchRL collector: each batch records the weight its policy had when the
    batch was collected."""

    def __init__(self, policy: torch.nn.Module) -> None:
        self.policy = policy
        self.weight_pushes = 0

    def __iter__(self):
        while True:
            yield float(self.policy.weight.detach().clone())

    def update_policy_weights_(self) -> None:
        self.weight_pushes += 1


def _run(overlap: bool, updates: int = 4) -> tuple[list[float], int]:
    actor = torch.nn.Linear(1, 1, bias=False)
    torch.nn.init.constant_(actor.weight, 0.0)
    behaviour = torch.nn.Linear(1, 1, bias=False)
    behaviour.load_state_dict(actor.state_dict())
    collector = RecordingCollector(behaviour)
    batches = Batches(collector, actor, behaviour, overlap)
    seen = []
    for k in range(updates):
        seen.append(next(batches))
        with torch.no_grad():
            actor.weight.fill_(k + 1.0)  # the "update" on batch k
    batches.close()
    return seen, collector.weight_pushes


def test_without_overlap_each_batch_uses_the_latest_weights() -> None:
    seen, pushes = _run(overlap=False)
    assert seen == [0.0, 1.0, 2.0, 3.0]
    assert pushes == 4


@pytest.mark.parametrize("repeat", range(3))
def test_with_overlap_each_batch_is_one_update_late(repeat: int) -> None:
    seen, _ = _run(overlap=True)
    # batch k+1 is collected while the learner updates on batch k, with the weights before it
    assert seen == [0.0, 0.0, 1.0, 2.0]


class HangingCollector(RecordingCollector):
    """A worker that hangs: its first batch arrives, the second never does."""

    def __iter__(self):
        yield 0.0
        threading.Event().wait()  # for ever (the fetching thread is a daemon)


@pytest.mark.parametrize("overlap", [True, False])
def test_a_hanging_worker_ends_the_wait_with_one_line(overlap: bool) -> None:
    behaviour = torch.nn.Linear(1, 1, bias=False)
    batches = Batches(
        HangingCollector(behaviour), torch.nn.Linear(1, 1, bias=False), behaviour, overlap, timeout_s=0.5
    )
    assert next(batches) == 0.0
    started = time.monotonic()
    with pytest.raises(WorkerTimeoutError, match=r"no batch from the workers in 0.5 s: a worker hangs"):
        next(batches)
    batches.close()  # does not wait for the hung batch either
    assert time.monotonic() - started < 5


def test_nothing_is_collected_after_the_last_batch() -> None:
    """``ahead = False`` before the run's last batch: the workers are idle once it has arrived, so
    they can end while the learner does its final evaluation (no batch to drain and drop)."""
    behaviour = torch.nn.Linear(1, 1, bias=False)
    collector = RecordingCollector(behaviour)
    started = []

    def counting():
        while True:
            started.append(len(started))
            yield 0.0

    batches = Batches(collector, torch.nn.Linear(1, 1, bias=False), behaviour, overlap=True)
    batches._iterator = counting()  # counts the batches asked of the workers
    next(batches)
    batches.ahead = False
    next(batches)
    time.sleep(0.05)
    assert len(started) == 2 and batches._thread is None
    batches.close()
