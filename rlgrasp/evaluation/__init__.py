"""Policy evaluation: seeded episodes in worker processes, metrics with intervals, plots, videos, reports.

Modules, one job each: ``source`` (checkpoint -> validated policy + env config), ``teacher`` (a
camera policy's teacher, checked against its env), ``episodes`` (running seeded episodes),
``metrics`` (rates, intervals, tables), ``plots``, ``views`` (what a camera saw, as pictures),
``video``, ``report`` (comparison across runs) and ``cli`` (the Hydra entry point).
"""

from rlgrasp.evaluation.source import EvaluationError

__all__ = ["EvaluationError"]
