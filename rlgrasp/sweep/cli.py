"""``rlgrasp-sweep`` / ``python scripts/sweep.py``: an Optuna search over training configs.

    rlgrasp-sweep experiment=grasp_ppo sweep=grasp_ppo [sweep.n_trials=40] [algo.optim.epochs=5 ...]
    rlgrasp-sweep sweep=grasp_ppo --summary          # tables, best config, plots of the stored study

``sweep=<name>`` and ``sweep.*`` overrides compose ``configs/sweep/<name>.yaml``; every other
argument is a training override applied to each trial. Start the same command in more processes
(or machines sharing the storage) with ``sweep.worker=1,2,...`` and they work on one study.
"""

from __future__ import annotations

import importlib.util
import logging
import sys

from rlgrasp.config import CONFIG_DIR
from rlgrasp.overrides import CommandLineError, OneLineParser, rewrite

EXTRA = 'rlgrasp-sweep needs optuna: pip install -e ".[sweep]"'


def is_sweep_override(item: str) -> bool:
    key = item.lstrip("+~").split("=", 1)[0]
    return key == "sweep" or key.startswith("sweep.")


def main(argv: list[str] | None = None) -> int:
    """``rlgrasp-sweep``: the exit code (bad input: one line on stderr; 1 for a command line Hydra
    refuses, 2 for a bad value; 130 when a signal stopped the sweep)."""
    parser = OneLineParser(
        prog="rlgrasp-sweep",
        description="Optuna hyperparameter sweep over rlgrasp training configs (docs/scaling.md).",
    )
    parser.add_argument("overrides", nargs="*", help="sweep=<name>, sweep.<key>=<v>, training key=value")
    parser.add_argument("--summary", action="store_true", help="only write the stored study's summary")
    parser.add_argument("--config-dir", default=CONFIG_DIR, help="the configs/ tree")
    args = parser.parse_args(argv)
    if importlib.util.find_spec("optuna") is None:
        print(f"error: {EXTRA}", file=sys.stderr)
        return 2
    # Lazy: optuna is an optional dependency (the sweep extra), imported by every sweep module.
    from rlgrasp.sweep.checks import SweepError
    from rlgrasp.sweep.runner import run_sweep

    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="[%(asctime)s][%(name)s][%(levelname)s] %(message)s")
    sweep_ov = [o for o in args.overrides if is_sweep_override(o)]
    train_ov = rewrite([o for o in args.overrides if not is_sweep_override(o)])
    try:
        result = run_sweep(sweep_ov, train_ov, args.config_dir, summary_only=args.summary)
    except (CommandLineError, SweepError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1 if isinstance(exc, CommandLineError) else 2
    for key in ("markdown", "csv", "best_config"):
        if result.get(key):
            print(f"{key}: {result[key]}")
    if "best_value" in result:
        print(f"best trial {result['best_number']}: value {result['best_value']:.4g} {result['best_params']}")
    return 130 if result.get("interrupted") else 0


if __name__ == "__main__":
    sys.exit(main())
