"""Hyperparameter sweeps with Optuna: search space from config, shared study storage, pruning on the
periodic evaluation, summaries. Entry point: ``rlgrasp-sweep`` / ``python scripts/sweep.py``.

Modules (the schema is ``rlgrasp.config.SweepConfig``): ``space`` (distributions from config),
``study`` (storage, sampler, pruner, resume bookkeeping), ``objective`` (one trial = one training
run per seed, composed by Hydra), ``score`` (a run's value from its evaluations), ``summary``
(tables, best config, plots), ``checks`` (refusing bad input before anything is written),
``runner`` (check, run, summarize) and ``cli`` (the command line).
"""
