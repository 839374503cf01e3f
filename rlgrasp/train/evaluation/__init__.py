"""Training's own evaluations, beside the loop as a callback (not ``rlgrasp.evaluation``, which
evaluates a finished checkpoint on its own).

``evaluations``: the ``Evaluations`` callback (the periodic and final evaluations, their curves, the
best checkpoint, the ``on_eval`` reports a sweep's pruner listens on); ``evaluate``: an ``Evaluator``
playing seeded episodes with the run's own env factory; ``eval_process``: the same in a process of its
own while training goes on (``eval.background``). Import the pieces from their modules; this package
stays light to import.
"""
