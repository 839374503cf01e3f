"""Small helpers shared by training, evaluation and sweeps."""

from __future__ import annotations

import multiprocessing as mp
import signal
import threading
from collections.abc import Callable, Mapping, Sequence
from multiprocessing.pool import Pool
from typing import Any


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


def pyplot() -> Any:
    """``matplotlib.pyplot`` drawing to files only (no display on workers, clusters or CI)."""
    # Imported here: only plots need matplotlib, and choosing its backend when rlgrasp.utils is
    # imported would take the display away from any program that imports it.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def spawn_pool(workers: int, initializer: Callable[..., None], initargs: tuple[Any, ...]) -> Pool:
    """A pool of spawned processes that leave Ctrl-C to the parent, from their first instruction.

    A Ctrl-C at a terminal reaches the whole process group. Ignoring SIGINT in a pool initializer
    is too late for a worker still importing torch (seconds on a busy machine): it prints a
    KeyboardInterrupt traceback. An ignored signal stays ignored across exec, and Python then
    installs no KeyboardInterrupt handler, so the workers are started with SIGINT ignored here.
    SIGINT is also blocked meanwhile: a Ctrl-C in that window waits for the parent's own handler
    instead of being lost (the kernel keeps a blocked signal pending even while it is ignored).
    """
    ctx = mp.get_context("spawn")
    if threading.current_thread() is not threading.main_thread():
        return ctx.Pool(workers, initializer=initializer, initargs=initargs)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        return ctx.Pool(workers, initializer=initializer, initargs=initargs)
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
