"""DAgger (``algo=distill``): a state teacher distilled into a camera student on the training core.

``schema``: its config and checks; ``algorithm``: the ``Algorithm`` the core builds (``DAgger``).
The teacher, the mixture the workers run and the labelled frames are the cameras' pieces
(``rlgrasp.vision.dagger``), shared with evaluation. This module stays light: the registry reads
``ALGORITHM`` without importing torch; ``rlgrasp.algos.dagger.DAgger`` loads on first use.
"""

from rlgrasp.algos.registry import AlgorithmEntry, lazy_attributes

ALGORITHM = AlgorithmEntry(
    name="distill",
    target="rlgrasp.algos.dagger.DAgger",
    schema="rlgrasp.algos.dagger.schema",
    aliases=("rlgrasp.vision.distill.DAgger",),  # where checkpoints written before the package name it
)

__getattr__ = lazy_attributes(__name__, "rlgrasp.algos.dagger.algorithm")
