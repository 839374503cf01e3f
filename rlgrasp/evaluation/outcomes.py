"""Why an episode failed, and success per object: what the held-out evaluation is read by.

A failure gets one reason, read from the env's per-step info (``grasped``, ``object_tilt``,
``object_extents``), so a scripted and a learned policy are judged by the same rules:

- ``too wide``: the object's narrowest horizontal extent exceeds what the hand can close across;
- ``tipped or rolled``: its tilt changed by more than 30 degrees before it was first held (a
  settled mesh may already rest tilted, so the change counts, not the tilt);
- ``never grasped``, ``slipped`` (held at some point, not at the end), ``held, not lifted``.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Sequence
from typing import Any

from rlgrasp.stats import wilson_interval

SUCCESS = "success"
TOO_WIDE = 0.075  # m: the Panda opens 8 cm; wider than this no grasp closes across it
TIPPED = math.radians(30)


def failure_reason(held: Sequence[bool], tilts: Sequence[float], extents: Sequence[float]) -> str:
    """One reason for a failed episode, from its per-step grasp flags, tilts and the object size."""
    if min(float(x) for x in extents[:2]) > TOO_WIDE:
        return "too wide"
    first_hold = list(held).index(True) if any(held) else len(held)
    start = float(tilts[0])
    if any(abs(float(t) - start) > TIPPED for t in tilts[: first_hold + 1]):
        return "tipped or rolled"
    if not any(held):
        return "never grasped"
    if not held[-1]:
        return "slipped"
    return "held, not lifted"


def success_by_object(objects: Sequence[str], outcomes: Sequence[str]) -> list[dict[str, Any]]:
    """Per object: episodes, successes, rate with its Wilson interval, the commonest failure.

    Sorted worst first (lowest rate, then most episodes), so the table opens on what to fix.
    """
    by_object: dict[str, list[str]] = collections.defaultdict(list)
    for name, outcome in zip(objects, outcomes):
        by_object[name].append(outcome)
    rows = []
    for name, results in by_object.items():
        n, k = len(results), results.count(SUCCESS)
        failures = collections.Counter(r for r in results if r != SUCCESS)
        low, high = wilson_interval(k, n)
        rows.append(
            {
                "object": name,
                "episodes": n,
                "successes": k,
                "rate": k / n,
                "ci95": [low, high],
                "main_failure": failures.most_common(1)[0][0] if failures else "",
            }
        )
    return sorted(rows, key=lambda r: (r["rate"], -r["episodes"], r["object"]))


def object_group(name: str) -> str:
    """``random_urdfs/140`` -> ``random_urdfs``; ``primitives/box`` stays (the kind is the group)."""
    head, _, tail = name.partition("/")
    return name if head == "primitives" else head
