"""Episode results -> rates with Wilson intervals, aggregates, ``episodes.csv`` and the summary table."""

from __future__ import annotations

import collections
import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rlgrasp.evaluation.episodes import EpisodeResult
from rlgrasp.evaluation.outcomes import success_by_object
from rlgrasp.stats import wilson_interval
from rlgrasp.utils import markdown_table

EPISODE_FIELDS = (
    "episode",
    "seed",
    "object",
    "outcome",
    "return",
    "length",
    "success_at_end",
    "success_once",
    "first_success_step",
    "grasped_at_end",
    "max_lift_height",
)


def rate(flags: Sequence[bool]) -> dict[str, Any]:
    """Successes, rate and its 95% Wilson interval (sane at 0/n and n/n, unlike mean +- 2 se)."""
    n, k = len(flags), int(sum(bool(f) for f in flags))
    low, high = wilson_interval(k, n)
    return {"rate": k / n, "successes": k, "episodes": n, "ci95": [low, high]}


def _mean(xs: Sequence[float]) -> float | None:
    return float(np.mean(xs)) if len(xs) else None


def summarize(results: Sequence[EpisodeResult]) -> dict[str, Any]:
    """The numbers of ``metrics.json`` that depend on the episodes only (identical for any worker count)."""
    if not results:
        raise ValueError("no episodes to summarize")
    returns = np.array([r.episode_return for r in results], dtype=float)
    firsts = [r.first_success_step for r in results if r.first_success_step is not None]
    return {
        "episodes": len(results),
        "success_at_end": rate([r.success_at_end for r in results]),
        "success_once": rate([r.success_once for r in results]),
        "grasped_at_end": rate([r.grasped_at_end for r in results]),
        "return": {
            "mean": float(returns.mean()),
            "std": float(returns.std(ddof=1)) if len(returns) > 1 else 0.0,
            "min": float(returns.min()),
            "max": float(returns.max()),
        },
        "mean_length": float(np.mean([r.length for r in results])),
        # Over the episodes that succeeded at least once (null when none did).
        "mean_steps_to_first_success": _mean(firsts),
        "outcomes": dict(collections.Counter(r.outcome for r in results).most_common()),
        "success_by_object": success_by_object([r.object for r in results], [r.outcome for r in results]),
    }


def compare_with_teacher(
    student: Sequence[EpisodeResult], teacher: Sequence[EpisodeResult], path: str
) -> dict[str, Any]:
    """The teacher's figures on the student's very episodes, the student/teacher success ratio and
    the paired outcomes (which episodes only one of them solves: where the camera falls short)."""
    if [r.seed for r in student] != [r.seed for r in teacher]:
        raise ValueError("the student and its teacher must run the same seeded episodes")
    s, t = rate([r.success_at_end for r in student]), rate([r.success_at_end for r in teacher])
    pairs = collections.Counter((a.success_at_end, b.success_at_end) for a, b in zip(student, teacher))
    return {
        "path": path,
        "success_at_end": t,
        "success_once": rate([r.success_once for r in teacher]),
        "return_mean": float(np.mean([r.episode_return for r in teacher])),
        # null when the teacher solved nothing: no ratio to speak of.
        "student_over_teacher": s["rate"] / t["rate"] if t["successes"] else None,
        "paired": {
            "both": pairs[(True, True)],
            "student_only": pairs[(True, False)],
            "teacher_only": pairs[(False, True)],
            "neither": pairs[(False, False)],
        },
    }


def episode_rows(
    results: Sequence[EpisodeResult], teacher: Sequence[EpisodeResult] = ()
) -> tuple[list[str], list[dict[str, Any]]]:
    """CSV columns (fixed fields, the teacher's outcome on the same episode if any, then every
    randomization parameter) and one row per episode."""
    params: list[str] = []
    for r in results:
        params += [k for k in r.randomization if k not in params]
    extra = ["teacher_success_at_end", "teacher_return"] if teacher else []
    rows = []
    for i, r in enumerate(results):
        row = {
            "episode": r.index,
            "seed": r.seed,
            "object": r.object,
            "outcome": r.outcome,
            "return": round(r.episode_return, 6),
            "length": r.length,
            "success_at_end": int(r.success_at_end),
            "success_once": int(r.success_once),
            "first_success_step": "" if r.first_success_step is None else r.first_success_step,
            "grasped_at_end": int(r.grasped_at_end),
            "max_lift_height": round(r.max_lift_height, 6),
        }
        if teacher:
            row.update(
                teacher_success_at_end=int(teacher[i].success_at_end),
                teacher_return=round(teacher[i].episode_return, 6),
            )
        row.update({k: r.randomization.get(k, "") for k in params})
        rows.append(row)
    return list(EPISODE_FIELDS) + extra + params, rows


def write_episodes_csv(
    path: Path, results: Sequence[EpisodeResult], teacher: Sequence[EpisodeResult] = ()
) -> Path:
    fields, rows = episode_rows(results, teacher)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    return path


def _fmt_rate(r: dict[str, Any]) -> str:
    lo, hi = r["ci95"]
    return f"{r['rate']:.1%} ({r['successes']}/{r['episodes']}) [{lo:.1%}, {hi:.1%}]"


def _fmt(x: float | None, spec: str = ".2f") -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def summary_table(metrics: dict[str, Any]) -> str:
    """A Markdown table (also what the console shows)."""
    m = metrics
    rows = [
        ("policy", m.get("policy_label", m.get("policy", ""))),
        ("objects", m.get("objects_label", "")),
        ("randomization", m.get("randomization_label", "")),
        *((key, m[f"{key}_label"]) for key in ("camera", "visual") if m.get(f"{key}_label")),
        (
            "episodes (seeds)",
            f"{m['episodes']} ({m['seeds'][0]}..{m['seeds'][-1]})" if m.get("seeds") else m["episodes"],
        ),
        ("success at end [95% Wilson]", _fmt_rate(m["success_at_end"])),
        ("success at any step [95% Wilson]", _fmt_rate(m["success_once"])),
        ("grasped at end", _fmt_rate(m["grasped_at_end"])),
        ("return mean +- std", f"{_fmt(m['return']['mean'])} +- {_fmt(m['return']['std'])}"),
        ("mean episode length", _fmt(m["mean_length"], ".1f")),
        ("mean steps to first success", _fmt(m["mean_steps_to_first_success"], ".1f")),
        *teacher_rows(m.get("teacher")),
    ]
    return markdown_table(("metric", "value"), rows)


def teacher_rows(t: dict[str, Any] | None) -> list[tuple[str, str]]:
    """The teacher's lines of the summary table (none without a teacher)."""
    if not t:
        return []
    p = t["paired"]
    return [
        ("teacher", t["path"]),
        ("teacher success at end, same episodes [95% Wilson]", _fmt_rate(t["success_at_end"])),
        ("student / teacher success at end", _fmt(t["student_over_teacher"])),
        (
            "episodes solved by both / student only / teacher only / neither",
            f"{p['both']} / {p['student_only']} / {p['teacher_only']} / {p['neither']}",
        ),
    ]


def outcome_table(metrics: dict[str, Any]) -> str:
    """Episodes per outcome: how the failures split."""
    n = metrics["episodes"]
    rows = [(name, count, f"{count / n:.1%}") for name, count in metrics["outcomes"].items()]
    return markdown_table(("outcome", "episodes", "share"), rows)


def object_table(metrics: dict[str, Any], most: int = 20) -> str:
    """The ``most`` objects with the lowest success (the whole list is in ``objects.csv``)."""
    rows = [
        (
            r["object"],
            r["episodes"],
            r["successes"],
            f"{r['rate']:.0%}",
            f"[{r['ci95'][0]:.0%}, {r['ci95'][1]:.0%}]",
            r["main_failure"],
        )
        for r in metrics["success_by_object"][:most]
    ]
    return markdown_table(("object", "episodes", "successes", "rate", "95% Wilson", "main failure"), rows)


def parameter_table(table: dict[str, list[dict[str, Any]]], most: int = 10) -> str:
    """The ``most`` parameters whose bins differ most (``rlgrasp.evaluation.plots.success_table``):
    the bins with the lowest and the highest success, each with its range and episodes."""

    def shown(b: dict[str, Any]) -> str:
        span = f"{b['low']:.3g}" if b["low"] == b["high"] else f"{b['low']:.3g}..{b['high']:.3g}"
        return f"{span}: {b['rate']:.0%} ({b['successes']}/{b['n']})"

    rows = []
    for name, bins in list(table.items())[:most]:
        ordered = sorted(bins, key=lambda b: b["rate"])
        low, high = ordered[0], ordered[-1]
        rows.append((name, shown(low), shown(high), f"{high['rate'] - low['rate']:.0%}"))
    return markdown_table(("parameter", "lowest bin", "highest bin", "spread"), rows)


def write_objects_csv(path: Path, metrics: dict[str, Any]) -> Path:
    fields = ("object", "episodes", "successes", "rate", "ci95_low", "ci95_high", "main_failure")
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(fields)
        for r in metrics["success_by_object"]:
            writer.writerow(
                [
                    r["object"],
                    r["episodes"],
                    r["successes"],
                    round(r["rate"], 4),
                    round(r["ci95"][0], 4),
                    round(r["ci95"][1], 4),
                    r["main_failure"],
                ]
            )
    return path


def write_json(path: Path, data: Any) -> Path:
    path.write_text(json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")
    return path


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serializable: {type(o).__name__}")
