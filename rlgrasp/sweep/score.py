"""A run's value from its evaluations (what training passes to ``on_eval``), for ``sweep.objective``:

- ``final``: the last evaluation's ``metric``.
- ``first_reach``: F x (1 - tie_break x s), F the env frames at the first evaluation whose ``metric``
  is >= ``threshold`` and s the final success; a run that never reaches it scores T x (2 - s), T its
  frame budget. A run that reaches the threshold is <= T and one that does not is >= T, so every
  run that reaches it beats every run that does not (minimize), and those that do not are ranked by
  their final success. The tie-break orders runs that reached it at the same evaluation by their
  final success; it never reorders runs that reached it at different evaluations while tie_break is
  under 1 / (evaluations per run): with the default 0.01, up to 100 evaluations.

What the pruner sees after each evaluation (``RunScore.add``) is the value the run would have if it
ended there with its budget T: on the objective's scale and in its direction at every step. Optuna's
median pruner compares the *best* of a trial's reports so far with the other trials' reports at the
same step; a projection onto the frames seen so far (frames x (2 - s)) would grow with the step and
leave a trial's first report its best, so no trial would ever be pruned.
"""

from __future__ import annotations

import math
from typing import Any

#: Success rates come from float32 counts: 0.9 of 30 episodes is 0.8999... (as benchmarks/bench_learning.py).
TOLERANCE = 1e-6
KINDS = ("final", "first_reach")


def first_reach_value(reached_at: int | None, success: float, budget: int, tie_break: float) -> float:
    """The ``first_reach`` value of a run that reached the threshold at ``reached_at`` frames (None:
    never) and whose (final) success is ``success``, on a budget of ``budget`` frames."""
    if reached_at is None:
        return float(budget) * (2.0 - success)
    return float(reached_at) * (1.0 - tie_break * success)


class RunScore:
    """Follows one run's evaluations; ``add`` returns the value to report, ``value`` the run's."""

    def __init__(self, objective: Any, metric: str, budget: int) -> None:
        self.kind, self.metric, self.budget = objective.kind, metric, int(budget)
        self.threshold, self.tie_break = float(objective.threshold), float(objective.tie_break)
        self.reached_at: int | None = None
        self.frames = 0
        self.last: dict[str, float] = {}
        self._value = math.nan

    def add(self, frames: int, metrics: dict[str, float]) -> float:
        """Record an evaluation at ``frames``; the value the run would have if it ended here."""
        if self.metric not in metrics:
            raise KeyError(f"sweep.metric={self.metric!r} is not an eval metric; have {sorted(metrics)}")
        self.frames, self.last = int(frames), dict(metrics)
        score = float(metrics[self.metric])
        if self.kind == "final":
            self._value = score
            return score
        if self.reached_at is None and score >= self.threshold - TOLERANCE:
            self.reached_at = self.frames
        # The budget, or the frames of an evaluation past it (the last batch can overshoot).
        self._value = first_reach_value(self.reached_at, score, max(self.budget, self.frames), self.tie_break)
        return self._value

    def value(self) -> float:
        """The run's value: that of its last evaluation (the final one); NaN before any."""
        return self._value

    def record(self) -> dict[str, Any]:
        """What the trial keeps of this run (a user attribute)."""
        out: dict[str, Any] = {"value": self.value(), "frames": self.frames}
        out[self.metric] = self.last.get(self.metric)
        if self.kind == "first_reach":
            out["reached_at"] = self.reached_at
        return out


def describe(cfg: Any) -> str:
    """What a trial's value is, in words (the summary's header)."""
    o, metric = cfg.objective, cfg.metric
    if o.kind == "first_reach":
        text = (
            f"Value: env frames at the first evaluation with {metric} >= {o.threshold}, x (1 - "
            f"{o.tie_break} x the final {metric}); a run that never reaches it: "
            f"{cfg.trial.total_frames:,} x (2 - the final {metric}). Lower is better."
        )
    else:
        text = f"Value: the final evaluation's {metric}."
    seeds = list(cfg.trial.seeds)
    return text + (f" Mean over the runs with seeds {seeds}." if len(seeds) > 1 else "")
