"""The training core: one run loop for every algorithm, and what runs around it.

At the top, the loop and its life: ``loop`` (``Trainer``, ``train``), ``lifecycle`` (how a run ends),
``callbacks`` (what runs beside the loop), ``parts`` (env factory, networks, collector), ``algorithm``
(a learner's seam; the learners are ``rlgrasp.algos``), ``checkpoint`` (written), ``resume`` and
``warm_start`` (where a run starts from), ``preemption`` (stop signals), ``validate`` (a config's
values), ``cli`` (``rlgrasp-train``). By role below it:

- ``collection``: the envs to the learner's batches (workers, backends, ADR's ranges out);
- ``evaluation``: training's own evaluations, a callback beside the loop;
- ``tracking``: where the curves and counters go (console, TensorBoard, W&B, MLflow).

Import the pieces from their modules (``rlgrasp.train.loop.train``,
``rlgrasp.train.checkpoint.save_checkpoint``); this package stays light to import.
"""
