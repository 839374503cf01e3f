"""Plots a user reads at a glance: success against each randomization parameter (the physics ones
and, for a camera env, the visual ones in a figure of their own), return distribution."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rlgrasp.evaluation.episodes import EpisodeResult
from rlgrasp.evaluation.outcomes import object_group
from rlgrasp.stats import wilson_interval
from rlgrasp.utils import pyplot


def binned_success(values: np.ndarray, success: np.ndarray, max_bins: int = 5) -> list[dict[str, Any]]:
    """Success rate with a Wilson interval per bin of ``values``.

    Few distinct values (an integer parameter such as ``action_delay``): one bin per value.
    Otherwise equal-count (quantile) bins, so every bin has enough episodes for an interval.
    """
    values, success = np.asarray(values, float), np.asarray(success, bool)
    distinct = np.unique(values)
    if distinct.size <= max_bins:
        groups = [(v, v, values == v) for v in distinct]
    else:
        n_bins = int(min(max_bins, max(2, values.size // 10)))
        edges = np.unique(np.quantile(values, np.linspace(0, 1, n_bins + 1)))
        idx = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
        groups = [(edges[b], edges[b + 1], idx == b) for b in range(len(edges) - 1)]
    out = []
    for low, high, mask in groups:
        n = int(mask.sum())
        if n == 0:
            continue
        k = int(success[mask].sum())
        lo, hi = wilson_interval(k, n)
        out.append(
            {
                "low": float(low),
                "high": float(high),
                "centre": float(values[mask].mean()),
                "n": n,
                "successes": k,
                "rate": k / n,
                "ci95": [lo, hi],
            }
        )
    return out


def varying_parameters(results: Sequence[EpisodeResult]) -> list[str]:
    """Parameters that actually vary across the episodes (a constant one explains nothing)."""
    names: list[str] = []
    for r in results:
        names += [k for k in r.randomization if k not in names]
    return [k for k in names if len({r.randomization.get(k) for r in results}) > 1]


#: The visual randomization's parameters (``rlgrasp.envs.visuals``) begin so.
VISUAL_PREFIX = "visual_"


def split_parameters(results: Sequence[EpisodeResult]) -> tuple[list[str], list[str]]:
    """The varying parameters as (physics, visual): what the robot meets and what the camera sees."""
    varying = varying_parameters(results)
    visual = [k for k in varying if k.startswith(VISUAL_PREFIX)]
    return [k for k in varying if k not in visual], visual


def success_table(
    results: Sequence[EpisodeResult], names: Sequence[str] | None = None, max_bins: int = 5
) -> dict[str, list[dict[str, Any]]]:
    """Binned success per parameter of ``names`` (default: every varying one), the most influential
    first (largest spread between bins)."""
    success = np.array([r.success_at_end for r in results])
    table = {
        name: binned_success(np.array([r.randomization[name] for r in results]), success, max_bins)
        for name in (varying_parameters(results) if names is None else names)
    }
    order = sorted(
        table, key=lambda k: -(max(b["rate"] for b in table[k]) - min(b["rate"] for b in table[k]))
    )
    return {name: table[name] for name in order}


def success_by_parameter(
    results: Sequence[EpisodeResult],
    path: Path,
    max_bins: int = 5,
    names: Sequence[str] | None = None,
    what: str = "randomization",
) -> dict[str, Any]:
    """One panel per parameter of ``success_table``; ``what`` names them in the title. Returns the table."""
    plt = pyplot()
    overall = np.mean([r.success_at_end for r in results])
    table = success_table(results, names, max_bins)
    order = list(table)
    cols = 4
    rows = max(1, math.ceil(len(order) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.7 * rows), squeeze=False)
    for ax, name in zip(axes.flat, order):
        bins = table[name]
        x = [b["centre"] for b in bins]
        y = [b["rate"] for b in bins]
        # max(0, ...): at 0/n and n/n the Wilson bound equals the rate up to rounding.
        err = [
            [max(0.0, b["rate"] - b["ci95"][0]) for b in bins],
            [max(0.0, b["ci95"][1] - b["rate"]) for b in bins],
        ]
        ax.errorbar(x, y, yerr=err, fmt="o-", capsize=3, color="tab:blue")
        for b in bins:
            if b["low"] != b["high"]:
                ax.axvspan(b["low"], b["high"], color="0.9" if bins.index(b) % 2 else "0.96", zorder=0)
        ax.axhline(overall, ls="--", color="tab:gray", lw=1)
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(order) :]:
        ax.axis("off")
    if not order:
        axes.flat[0].text(0.5, 0.5, f"no {what} parameter varies", ha="center", va="center")
    fig.suptitle(
        f"success at end vs {what} (bins with 95% Wilson intervals; dashed: overall {overall:.0%})",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return table


def return_histogram(results: Sequence[EpisodeResult], path: Path) -> Path:
    """Returns of successful and failed episodes stacked: a bimodal policy shows as two humps."""
    plt = pyplot()
    returns = np.array([r.episode_return for r in results])
    ok = np.array([r.success_at_end for r in results])
    bins = np.histogram_bin_edges(returns, bins=min(30, max(5, len(returns) // 4)))
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.hist(
        [returns[ok], returns[~ok]],
        bins=bins,
        stacked=True,
        color=["tab:green", "tab:red"],
        label=[f"success at end ({ok.sum()})", f"failure ({(~ok).sum()})"],
    )
    ax.axvline(returns.mean(), color="k", ls="--", lw=1, label=f"mean {returns.mean():.2f}")
    ax.set_xlabel("episode return")
    ax.set_ylabel("episodes")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def success_by_object_plot(metrics: dict[str, Any], path: Path, most: int = 30) -> Path:
    """Left: success per object group; right: the ``most`` objects that fail most (Wilson bars)."""
    plt = pyplot()
    rows = metrics["success_by_object"]
    groups: dict[str, list[int]] = {}
    for r in rows:
        n_k = groups.setdefault(object_group(r["object"]), [0, 0])
        n_k[0] += r["episodes"]
        n_k[1] += r["successes"]
    worst = rows[:most][::-1]  # the worst at the top of a horizontal bar chart
    height = max(3.0, 0.22 * max(len(worst), len(groups)) + 1.2)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, height), gridspec_kw={"width_ratios": [1, 2]})
    for ax, labels, counts in (
        (left, list(groups), [tuple(v) for v in groups.values()]),
        (right, [r["object"] for r in worst], [(r["episodes"], r["successes"]) for r in worst]),
    ):
        rates = [k / n for n, k in counts]
        bounds = [wilson_interval(k, n) for n, k in counts]
        err = [
            [max(0.0, r - lo) for r, (lo, _) in zip(rates, bounds)],
            [max(0.0, hi - r) for r, (_, hi) in zip(rates, bounds)],
        ]
        ax.barh(range(len(labels)), rates, xerr=err, color="tab:blue", capsize=2)
        ax.set_yticks(
            range(len(labels)), [f"{lab} (n={n})" for lab, (n, _) in zip(labels, counts)], fontsize=7
        )
        ax.set_xlim(0, 1.02)
        ax.set_xlabel("success at end")
    left.set_title("per object group", fontsize=9)
    right.set_title(f"the {len(worst)} objects with the lowest success", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
