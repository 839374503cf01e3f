"""``rlgrasp-sweep`` / ``python scripts/sweep.py``: an Optuna search over training configs.

    rlgrasp-sweep experiment=grasp_ppo sweep=grasp_ppo [sweep.n_trials=40] [algo.epochs=5 ...]
    rlgrasp-sweep sweep=grasp_ppo --summary          # tables, best config, plots of the stored study

``sweep=<name>`` and ``sweep.*`` overrides compose ``configs/sweep/<name>.yaml``; every other
argument is a training override applied to each trial. Start the same command in more processes
(or machines sharing the storage) with ``sweep.worker=1,2,...`` and they work on one study.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from omegaconf import OmegaConf

from rlgrasp.config import CONFIG_DIR

log = logging.getLogger("rlgrasp.sweep")


def is_sweep_override(item: str) -> bool:
    key = item.lstrip("+~").split("=", 1)[0]
    return key == "sweep" or key.startswith("sweep.")


def run_sweep(
    sweep_overrides: list[str],
    train_overrides: list[str],
    config_dir: str | Path = CONFIG_DIR,
    summary_only: bool = False,
) -> dict:
    """Run (or resume, or join) the study until it holds ``n_trials`` finished trials; summarize."""
    import optuna

    from rlgrasp.compose import compose_sweep, compose_train
    from rlgrasp.sweep.objective import Objective
    from rlgrasp.sweep.space import parse_space
    from rlgrasp.sweep.study import (
        enqueue_initial,
        fail_dead_trials,
        n_finished,
        open_study,
        requeue_interrupted,
        study_dir,
    )
    from rlgrasp.sweep.summary import write_summary

    cfg = compose_sweep(sweep_overrides, config_dir)
    out_dir = study_dir(cfg)
    if summary_only or cfg.summary_only:
        study = open_study(cfg, create=False)
        return write_summary(study, out_dir, config_dir, cfg.plots)

    space = parse_space(OmegaConf.to_container(cfg.params, resolve=True))
    # Fail now, not in trial 0, on a bad training override.
    compose_train([*train_overrides, *cfg.overrides, "paths.output_dir=/tmp/unused"], config_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "sweep.yaml").write_text(OmegaConf.to_yaml(cfg))
    study = open_study(cfg)
    enqueue_initial(study, OmegaConf.to_container(cfg.enqueue, resolve=True), space)
    dead = fail_dead_trials(study)
    retried = requeue_interrupted(study)
    log.info(
        "study %s in %s: %d/%d trials finished%s%s",
        cfg.study_name,
        out_dir,
        n_finished(study),
        cfg.n_trials,
        f"; trials {dead} of dead processes marked interrupted" if dead else "",
        f"; retrying interrupted trials {retried}" if retried else "",
    )
    interrupted = _optimize(study, Objective(cfg, config_dir, train_overrides, space), cfg)
    study = optuna.load_study(study_name=cfg.study_name, storage=study._storage)
    result = write_summary(study, out_dir, config_dir, cfg.plots)
    result["interrupted"] = interrupted
    result["finished"] = n_finished(study)
    return result


def _optimize(study, objective, cfg) -> bool:
    """One trial at a time until ``n_trials`` are finished or ``timeout_min`` is spent; returns True
    if a signal stopped the sweep."""
    from rlgrasp.sweep.objective import Interrupted, catch_signals, stop_requested
    from rlgrasp.sweep.study import n_finished

    deadline = time.monotonic() + cfg.timeout_min * 60 if cfg.timeout_min else float("inf")
    with catch_signals():
        try:
            while n_finished(study) < cfg.n_trials and time.monotonic() < deadline:
                study.optimize(objective, n_trials=1, catch=(Exception,), gc_after_trial=True)
                if stop_requested():
                    raise KeyboardInterrupt
        except Interrupted as exc:
            log.warning("%s: the sweep stops; run the same command again to resume", exc)
            return True
        except KeyboardInterrupt:
            log.warning("interrupted between trials; run the same command again to resume")
            return True
    return False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="rlgrasp-sweep",
        description="Optuna hyperparameter sweep over rlgrasp training configs (docs/SCALING.md).",
    )
    parser.add_argument("overrides", nargs="*", help="sweep=<name>, sweep.<key>=<v>, training key=value")
    parser.add_argument("--summary", action="store_true", help="only write the stored study's summary")
    parser.add_argument("--config-dir", default=CONFIG_DIR, help="the configs/ tree")
    args = parser.parse_args(argv)
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="[%(asctime)s][%(name)s][%(levelname)s] %(message)s")
    sweep_ov = [o for o in args.overrides if is_sweep_override(o)]
    train_ov = [o for o in args.overrides if not is_sweep_override(o)]
    result = run_sweep(sweep_ov, train_ov, args.config_dir, summary_only=args.summary)
    for key in ("markdown", "csv", "best_config"):
        if result.get(key):
            print(f"{key}: {result[key]}")
    if "best_value" in result:
        print(f"best trial {result['best_number']}: value {result['best_value']:.4g} {result['best_params']}")
    return 130 if result.get("interrupted") else 0


if __name__ == "__main__":
    sys.exit(main())
