"""SAC (``algo=sac``), and with ``algo.demos`` RLPD, on the training core.

``schema``: its config and checks; ``algorithm``: the ``Algorithm`` the core builds (``SAC``, its
replay and step); ``critics``: the critics as one batched network; ``losses``: the losses on them and
the target critics' soft update; ``replay_files``: the replay buffer on disk beside the checkpoints.
This module stays light: the registry reads ``ALGORITHM`` without importing torch, and
``rlgrasp.algos.sac.SAC`` (the class configs and checkpoints name) loads on first use.
"""

from rlgrasp.algos.registry import AlgorithmEntry, lazy_attributes

ALGORITHM = AlgorithmEntry(name="sac", target="rlgrasp.algos.sac.SAC", schema="rlgrasp.algos.sac.schema")

__getattr__ = lazy_attributes(__name__, "rlgrasp.algos.sac.algorithm")
