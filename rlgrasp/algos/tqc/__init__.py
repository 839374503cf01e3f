"""TQC (``algo=tqc``): truncated quantile critics, SAC with distributional critics whose pooled target
drops its highest atoms (Kuznetsov et al. 2020), on the training core.

``schema``: its config (SAC's, with the quantiles in ``algo.loss``) and checks; ``algorithm``: the
``Algorithm`` the core builds (``TQC``, SAC with quantile critics); ``losses``: TQC's losses. This
module stays light: the registry reads ``ALGORITHM`` without importing torch; ``rlgrasp.algos.tqc.TQC``
loads on first use.
"""

from rlgrasp.algos.registry import AlgorithmEntry, lazy_attributes

ALGORITHM = AlgorithmEntry(name="tqc", target="rlgrasp.algos.tqc.TQC", schema="rlgrasp.algos.tqc.schema")

__getattr__ = lazy_attributes(__name__, "rlgrasp.algos.tqc.algorithm")
