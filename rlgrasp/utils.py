"""Small helpers shared by training, evaluation and sweeps."""

from __future__ import annotations

import contextlib
import ctypes
import json
import logging
import multiprocessing
import multiprocessing.spawn
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any

from omegaconf import OmegaConf


def plain(value: Any) -> Any:
    """A config node as plain containers (resolved), anything else as it is: what env factories,
    checkpoints and comparisons with a checkpoint's dict take."""
    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


def flatten(
    node: Mapping[str, Any], prefix: str = "", leaf: Callable[[Any], bool] | None = None
) -> dict[str, Any]:
    """``{"algo": {"lr": x}}`` -> ``{"algo.lr": x}``; ``leaf(node)`` true stops the descent."""
    out: dict[str, Any] = {}
    for key, value in node.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping) and not (leaf and leaf(value)):
            out.update(flatten(value, path + ".", leaf))
        else:
            out[path] = value
    return out


def markdown_table(head: Sequence[Any], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table with padded columns (readable as plain text too)."""
    cells = [[str(c) for c in head], *([str(c) for c in row] for row in rows)]
    widths = [max(len(row[i]) for row in cells) for i in range(len(head))]

    def line(row: list[str]) -> str:
        return "| " + " | ".join(c.ljust(w) for c, w in zip(row, widths)) + " |"

    return "\n".join(
        [line(cells[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|", *map(line, cells[1:])]
    )


class Progress:
    """``progress(done, total)`` for a pool's results: logs ``done/total episodes`` to ``logger`` at
    each fifth of the way."""

    def __init__(self, logger: logging.Logger) -> None:
        self.logger, self.logged = logger, 0

    def __call__(self, done: int, total: int) -> None:
        fifth = 5 * done // total
        if fifth > self.logged or done == total:
            self.logged = fifth
            self.logger.info("  %d/%d episodes", done, total)


def pyplot() -> Any:
    """``matplotlib.pyplot`` drawing to files only (no display on workers, clusters or CI)."""
    # Imported here: only plots need matplotlib, and choosing its backend when rlgrasp.utils is
    # imported would take the display away from any program that imports it.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


_PR_SET_PDEATHSIG = 1  # linux/prctl.h
#: How often a child's watchdog looks whether its parent is still there (it ends within this of it).
PARENT_POLL_S = 0.2
_WATCHING = False  # die_with_parent ran in this process
#: Python run first in every child this process spawns, before the child imports anything: its main
#: module's imports (torch, PyBullet) take seconds, and a parent killed then would leave it running.
#: The parent writes its own pid in, so a child whose parent died before this ran knows it
#: (``os.getppid()`` would then name pid 1, or a subreaper, and the child would wait on that).
_PARENT_GUARD = """import os, sys, threading, time
def _rlgrasp_parent_guard(parent={pid}, poll={poll!r}):
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            ctypes.CDLL(None).prctl({pdeathsig}, 9)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:
        os._exit(1)
    def watch():
        while os.getppid() == parent:
            time.sleep(poll)
        os._exit(1)
    threading.Thread(target=watch, name="rlgrasp-parent-watch", daemon=True).start()
_rlgrasp_parent_guard()
del _rlgrasp_parent_guard
"""
_SPAWN_COMMAND_LINE: Callable[..., list[str]] | None = None


def guard_spawned_children() -> None:
    """Have every process this one spawns (``multiprocessing``'s spawn: pools, TorchRL's collector
    workers, the evaluation process) end within ``PARENT_POLL_S`` of this process's end, from its
    first instruction (``_PARENT_GUARD``); idempotent.

    multiprocessing offers no hook that runs in the child before it imports the parent's main module,
    so its spawn command line (``python -c "<program>"``) is wrapped here to start with the guard.
    The pid is this process's at each launch: a spawned child's parent is always the process that
    launched it, so the guard is right for every spawned child, whoever asked for it."""
    global _SPAWN_COMMAND_LINE
    if _SPAWN_COMMAND_LINE is not None:
        return
    _SPAWN_COMMAND_LINE = original = multiprocessing.spawn.get_command_line

    def guarded(**kwds: Any) -> list[str]:
        cmd = list(original(**kwds))
        if "-c" in cmd:
            i = cmd.index("-c") + 1
            guard = _PARENT_GUARD.format(pid=os.getpid(), poll=PARENT_POLL_S, pdeathsig=_PR_SET_PDEATHSIG)
            cmd[i] = guard + cmd[i]
        return cmd

    multiprocessing.spawn.get_command_line = guarded


def die_with_parent() -> None:
    """End this process when the process that started it ends, however it ends (``kill -9``
    included); nothing in the main process of a command, which has no parent of ours.

    A spawned worker blocks on its task queue or steps envs; nothing it does notices the parent's
    death, so a killed command left its workers running, orphaned, for good. The parent is the one
    multiprocessing recorded when it created this process (``parent_process().pid``), known from
    before this process started: ``os.getppid()`` read now would name pid 1 (or a subreaper) if the
    parent had died while this one was still importing, and the watch would wait on that forever.
    Two means, as neither covers every case alone: Linux's ``PR_SET_PDEATHSIG`` has the kernel send
    SIGKILL at once, even to a child stuck in C code holding the GIL, but exists on Linux only; a
    daemon thread that compares ``os.getppid()`` with the recorded parent covers the rest. (The signal
    follows the parent *thread* that started the child: every worker here is started from its
    parent's main thread.) A child spawned by a process that called ``guard_spawned_children`` is
    watched from its first instruction already; this covers the others.
    """
    global _WATCHING
    parent_process = multiprocessing.parent_process()
    if parent_process is None or _WATCHING:
        return
    _WATCHING, parent = True, parent_process.pid
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # it died before the signal was asked for
        os._exit(1)
    threading.Thread(target=_exit_without, args=(parent,), name="rlgrasp-parent-watch", daemon=True).start()


def _exit_without(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


# glibc's mallopt parameters (<malloc.h>) and the largest mmap threshold it takes on 64-bit.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD_MAX = 32 << 20


def keep_freed_memory(trim_threshold: int = 256 << 20) -> bool:
    """Have glibc serve blocks of up to 32 MiB from its heap and keep up to ``trim_threshold`` bytes
    of freed memory, rather than map each large block afresh and hand it back when freed.

    A camera learner allocates and frees tens of megabytes of image tensors every gradient step
    (augmented copies, float conversions, activations); left to its defaults, glibc maps many of them
    anew each time, and each fresh mapping is paid again in page faults (what that costs an RGB
    step: docs/history/algorithms.md). Set at run time through ``mallopt`` so that no environment
    variable is needed before the interpreter starts. False (and nothing changed) where the C library
    is not glibc."""
    try:
        libc = ctypes.CDLL(None)
        set_option = libc.mallopt
    except (OSError, AttributeError):
        return False
    heap = set_option(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_MAX)
    return bool(heap and set_option(_M_TRIM_THRESHOLD, trim_threshold))


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[list[int]]:
    """SIGTERM (``kill``, a scheduler) stops the command as Ctrl-C does, unwinding through a worker
    pool's exit (which terminates the workers) and the removal of partial output. Python's default
    would end the process at once, before any of that. Yields the signals caught."""
    caught: list[int] = []

    def interrupt(signum: int, frame: Any) -> None:
        caught.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield caught
    finally:
        signal.signal(signal.SIGTERM, previous)


class _SpawnIgnoringCtrlC(SpawnProcess):
    """A spawned process born with SIGINT blocked (see ``SpawnPool``), which ends with its parent
    (``die_with_parent``). The parent blocks SIGINT for the launch, and a Ctrl-C that arrives then is
    delivered to it when the launch is done: blocked, not ignored, so that it is late rather than
    lost (a busy machine can take seconds to launch)."""

    @staticmethod
    def _Popen(process_obj: Any) -> Any:  # noqa: N802 (multiprocessing's name)
        guard_spawned_children()
        if threading.current_thread() is not threading.main_thread():  # the pool replacing a worker
            return SpawnProcess._Popen(process_obj)
        previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            return SpawnProcess._Popen(process_obj)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)

    def run(self) -> None:
        die_with_parent()  # the child's first instruction of ours: see die_with_parent
        super().run()


class SpawnContextIgnoringCtrlC(SpawnContext):
    """multiprocessing's spawn context, its processes born with SIGINT blocked (see ``SpawnPool``);
    hand them large arguments after the launch, as ``SpawnPool`` does."""

    Process = _SpawnIgnoringCtrlC


def _init_from_queue(handoff: Any) -> None:
    die_with_parent()
    initializer, initargs = handoff.get()
    initializer(*initargs)


class WorkerDiedError(RuntimeError):
    """A pool worker ended abruptly (killed, out of memory, or crashed inside PyBullet)."""


class SpawnPool:
    """Spawned worker processes that leave Ctrl-C to the parent, from their first instruction, and
    whose death is an error rather than a wait.

    A Ctrl-C at a terminal reaches the whole process group. Ignoring SIGINT in a pool initializer
    is too late for a worker still importing torch (seconds on a busy machine): it prints a
    KeyboardInterrupt traceback. A blocked signal stays blocked across exec and is never delivered,
    so each worker is launched while this process blocks SIGINT. ``initargs`` (a policy's weights)
    follow through a queue: passed at launch, they would keep the launch, and the parent's Ctrl-C,
    waiting until the worker had imported torch.

    Built on ``concurrent.futures.ProcessPoolExecutor`` rather than ``multiprocessing.Pool``: a Pool
    replaces a worker that died and waits forever for the task it held; the executor raises
    ``BrokenProcessPool``, turned here into ``WorkerDiedError``. Leaving the ``with`` block on an
    exception (Ctrl-C included) terminates the workers instead of waiting for their tasks.
    """

    def __init__(self, workers: int, initializer: Callable[..., None], initargs: tuple[Any, ...]):
        guard_spawned_children()
        context = SpawnContextIgnoringCtrlC()
        handoff = context.Queue()
        handoff.cancel_join_thread()  # a pool ended before its workers read their copies must not wait
        self._executor = ProcessPoolExecutor(workers, context, _init_from_queue, (handoff,))
        for _ in range(workers):
            handoff.put((initializer, initargs))

    def imap_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[Any]:
        """``fn(item)`` for every item, in the order they finish; all are submitted at once."""
        return self._results([self._executor.submit(fn, item) for item in items])

    @staticmethod
    def _results(futures: list[Any]) -> Iterator[Any]:
        for future in as_completed(futures):
            try:
                yield future.result()
            except BrokenProcessPool:
                raise WorkerDiedError(
                    "a worker process died (killed, out of memory, or crashed in the physics engine)"
                ) from None

    def __enter__(self) -> SpawnPool:
        return self

    def __exit__(self, kind: Any, *_: Any) -> None:
        if kind is None:
            self._executor.shutdown(wait=True)
            return
        # The executor's own shutdown waits for running tasks; Python 3.11 has no public way to
        # stop them (3.14 adds terminate_workers), so its process table is read directly.
        processes = list(getattr(self._executor, "_processes", {}).values())
        manager = getattr(self._executor, "_executor_manager_thread", None)
        self._executor.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()
        for process in processes:
            process.join(timeout=10)
        # The executor's thread closes its wake-up pipe when it sees the workers gone; if that races
        # the interpreter's exit hook writing to the pipe, Python prints an OSError traceback.
        # Waiting for the thread here leaves the pipe closed before the hook runs.
        if manager is not None:
            manager.join(timeout=10)


def dumps(meta: dict[str, Any]) -> str:
    """Indented JSON with short lists on one line (the layout stays readable): policy files' and
    policy folders' ``config.json``."""
    text = json.dumps(meta, indent=2)
    return re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text) + "\n"
