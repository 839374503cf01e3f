"""What a sweep leaves behind, in its study directory: ``trials.csv``, ``trials.md``, the best
parameters as a ready-to-run experiment config, and Optuna's plots as PNG.

The best config is written as ``<study dir>/configs/experiment/<study>_best.yaml``; run it with
``python scripts/train.py --config-dir <study dir>/configs experiment=<study>_best`` or copy it to
``configs/experiment/``. It keeps the experiment's own frame budget (the trials' is a sweep budget).
"""

from __future__ import annotations

import csv
import logging
import math
import warnings
from pathlib import Path
from typing import Any

import optuna
from omegaconf import OmegaConf
from optuna.trial import FrozenTrial, TrialState

from rlgrasp.compose import compose_train
from rlgrasp.sweep.study import ATTR_INTERRUPTED, ATTR_OBJECTIVE, ATTR_RETRY_OF, ATTR_RUNS
from rlgrasp.utils import markdown_table, pyplot

log = logging.getLogger("rlgrasp.sweep")

#: Override keys that describe where/how long a trial ran, not what it was: left out of the best config
#: (``algo.schedule.anneal_lr_frames``: ``trial.lr_schedule=experiment`` sets it to the experiment's frames).
RUN_KEYS = (
    "paths.",
    "total_frames",
    "time_budget_min",
    "resume",
    "hydra.",
    "experiment_name",
    "algo.schedule.anneal_lr_frames",
)


def _seed_values(t: FrozenTrial) -> dict[str, float]:
    """``value_seed<n>`` -> the value of the trial's run with seed n (trials with ``trial.seeds``)."""
    return {f"value_seed{r['seed']}": r["value"] for r in t.user_attrs.get(ATTR_RUNS, []) if "seed" in r}


def trial_rows(study: optuna.Study) -> tuple[list[str], list[dict[str, Any]]]:
    """One row per trial: number, state, value, each seed's value (several seeds per trial), last
    reported step, duration, parameters, notes."""
    trials = study.get_trials(deepcopy=False)
    names = sorted({k for t in trials for k in t.params})
    per_seed = []  # with one run per trial, its value is the trial's
    if any(len(t.user_attrs.get(ATTR_RUNS, [])) > 1 for t in trials):
        found = {k for t in trials for k in _seed_values(t)}
        per_seed = sorted(found, key=lambda k: int(k.removeprefix("value_seed")))
    header = ["number", "state", "value", *per_seed, "last_step", "duration_s", *names, "note"]
    rows = []
    for t in trials:
        note = []
        if t.user_attrs.get(ATTR_INTERRUPTED):
            note.append("interrupted")
        if ATTR_RETRY_OF in t.user_attrs:
            note.append(f"retry of {t.user_attrs[ATTR_RETRY_OF]}")
        if t.state == TrialState.FAIL and t.user_attrs.get("error"):
            note.append(str(t.user_attrs["error"]).splitlines()[0][:100])
        rows.append(
            {
                "number": t.number,
                "state": t.state.name,
                "value": t.value,
                **{k: _seed_values(t).get(k) for k in per_seed},
                "last_step": t.last_step,
                "duration_s": round(t.duration.total_seconds(), 1) if t.duration else None,
                **{k: t.params.get(k) for k in names},
                "note": "; ".join(note),
            }
        )
    return header, rows


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v).replace("|", "\\|")


def write_tables(study: optuna.Study, out_dir: Path) -> tuple[Path, Path]:
    header, rows = trial_rows(study)
    csv_path, md_path = out_dir / "trials.csv", out_dir / "trials.md"
    with csv_path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=header)
        w.writeheader()
        w.writerows(rows)
    sign = -1 if study.direction == optuna.study.StudyDirection.MAXIMIZE else 1
    ranked = sorted(rows, key=lambda r: (r["value"] is None, sign * (r["value"] or 0.0), r["number"]))
    counts = {s.name: sum(r["state"] == s.name for r in rows) for s in TrialState}
    lines = [
        f"# Study `{study.study_name}` ({study.direction.name.lower()})",
        "",
        *([str(study.user_attrs[ATTR_OBJECTIVE]), ""] if ATTR_OBJECTIVE in study.user_attrs else []),
        ", ".join(f"{n} {k.lower()}" for k, n in counts.items() if n),
        "",
        markdown_table(header, [[_fmt(r[h]) for h in header] for r in ranked]),
        "",
    ]
    md_path.write_text("\n".join(lines))
    return csv_path, md_path


def _split_override(item: str) -> tuple[str, str] | None:
    if item.startswith("~") or "=" not in item:
        return None
    key, _, value = item.lstrip("+").partition("=")
    return key, value


def best_config_text(study: optuna.Study, best: FrozenTrial, config_dir: Path) -> str:
    """An experiment config reproducing ``best``: its base experiment, group choices and values."""
    overrides = list(best.user_attrs.get("overrides", []))
    composed = compose_train(overrides, config_dir)
    base, groups, values = None, [], {}
    for item in overrides:
        split = _split_override(item)
        if split is None:
            continue
        key, value = split
        if key == "experiment":
            base = None if value == "null" else value
        elif "." not in key and (config_dir / key).is_dir():
            groups.append((key, value))
        elif not key.startswith(RUN_KEYS):
            values[key] = OmegaConf.select(composed, key)
    name = f"{study.study_name}_best"
    nested: dict[str, Any] = {"experiment_name": name}
    for key, value in values.items():
        node = nested
        *parents, leaf = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = OmegaConf.to_container(value) if OmegaConf.is_config(value) else value
    defaults = ([f"  - {base}"] if base else []) + [f"  - override /{g}: {v}" for g, v in groups]
    body = OmegaConf.to_yaml(OmegaConf.create(nested))
    header = [
        "# @package _global_",
        f"# Best trial {best.number} of study '{study.study_name}': value {best.value:.4g}.",
        f"# Parameters: {best.params}",
        "# Written by rlgrasp-sweep. Run: python scripts/train.py --config-dir <this file's configs dir>"
        f" experiment={name}",
        "# The frame budget is the base experiment's (trials ran on the sweep's per-trial budget).",
    ]
    if defaults:
        header += ["defaults:", *defaults, "  - _self_"]
    return "\n".join(header) + "\n\n" + body


def write_best_config(study: optuna.Study, out_dir: Path, config_dir: Path) -> Path | None:
    complete = [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]
    if not complete:
        log.warning("no completed trial yet: no best config")
        return None
    best = study.best_trial
    path = out_dir / "configs" / "experiment" / f"{study.study_name}_best.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(best_config_text(study, best, Path(config_dir)))
    return path


def write_plots(study: optuna.Study, out_dir: Path) -> list[Path]:
    """History, parameter importances, parallel coordinates, intermediate values (PNG).

    A plot Optuna cannot draw yet (e.g. importances with fewer than two completed trials) is
    skipped with a log line. Importances use PED-ANOVA, which needs no scikit-learn.
    """
    # Lazy: Optuna's matplotlib backend imports matplotlib, which only the plots need.
    from optuna.importance import PedAnovaImportanceEvaluator
    from optuna.visualization import matplotlib as ovm

    plt = pyplot()

    plots = {
        "history": lambda: ovm.plot_optimization_history(study),
        "importances": lambda: ovm.plot_param_importances(study, evaluator=PedAnovaImportanceEvaluator()),
        "parallel_coordinates": lambda: ovm.plot_parallel_coordinate(study),
        "intermediate_values": lambda: ovm.plot_intermediate_values(study),
    }
    out = []
    for name, draw in plots.items():
        path = out_dir / "plots" / f"{name}.png"
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ax = draw()
            fig = (ax.flat[0] if hasattr(ax, "flat") else ax).figure
            path.parent.mkdir(parents=True, exist_ok=True)
            fig.set_size_inches(9, 5.5)
            fig.tight_layout()
            fig.savefig(path, dpi=100)
            out.append(path)
        except Exception as exc:  # noqa: BLE001 - a plot is a nicety; the tables are what matter
            log.info("plot %s skipped: %s", name, exc)
        finally:
            plt.close("all")
    return out


def write_summary(
    study: optuna.Study, out_dir: str | Path, config_dir: str | Path, plots: bool = True
) -> dict[str, Any]:
    """Everything above; returns the paths written and the best trial's number/value/params."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path, md_path = write_tables(study, out_dir)
    best_path = write_best_config(study, out_dir, Path(config_dir))
    result: dict[str, Any] = {"csv": csv_path, "markdown": md_path, "best_config": best_path, "plots": []}
    if best_path is not None:
        best = study.best_trial
        result.update(best_number=best.number, best_value=best.value, best_params=best.params)
    if plots:
        result["plots"] = write_plots(study, out_dir)
    value = result.get("best_value", math.nan)
    log.info("summary in %s (best value %.4g, %d plots)", out_dir, value, len(result["plots"]))
    return result
