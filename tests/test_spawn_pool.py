"""The evaluation's and the demonstration recorder's worker pool: results come back, a worker that
dies is an error rather than a wait, and leaving on an exception stops workers mid-task."""

from __future__ import annotations

import os
import time

import pytest

from rlgrasp.utils import SpawnPool, WorkerDiedError

_STATE: dict[str, int] = {}


def _init(offset: int) -> None:
    _STATE["offset"] = offset


def _shifted(x: int) -> int:
    return x + _STATE["offset"]


def _dies_on_three(x: int) -> int:
    if x == 3:
        os._exit(9)  # as a segfault or the OOM killer would end it: no exception, no cleanup
    return x


def _sleeps(x: int) -> int:
    time.sleep(60)
    return x


def test_each_item_comes_back_through_the_initialized_workers() -> None:
    with SpawnPool(2, _init, (100,)) as pool:
        assert sorted(pool.imap_unordered(_shifted, range(6))) == list(range(100, 106))


def test_a_worker_that_dies_is_an_error_not_a_wait() -> None:
    start = time.monotonic()
    with pytest.raises(WorkerDiedError, match="worker process died"):
        with SpawnPool(2, _init, (0,)) as pool:
            list(pool.imap_unordered(_dies_on_three, range(6)))
    assert time.monotonic() - start < 60


def test_leaving_on_an_exception_stops_workers_mid_task() -> None:
    start = time.monotonic()
    with pytest.raises(KeyError):
        with SpawnPool(2, _init, (0,)) as pool:
            pool.imap_unordered(_sleeps, range(2))  # submitted at once: the workers start them
            time.sleep(2)  # the workers are inside their 60 s tasks
            raise KeyError("the caller stopped")
    assert time.monotonic() - start < 30  # not the 60 s the tasks would take
