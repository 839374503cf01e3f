"""What runs beside the training loop, the lightning-hydra-template's way: the loop calls each
callback's hooks at fixed points and knows nothing of what they do.

Two ship: the evaluations (``rlgrasp.train.evaluation.evaluations``: periodic and final evaluations, the best
checkpoint, the sweep's reports through ``on_eval``) and ADR (``rlgrasp.train.collection.adr_sync``: its
ranges' curves, state and file). A hook a callback does not need stays this base's no-op.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


class Callback:
    """The hooks, in the order a run calls them."""

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """A resumed run's checkpoint (the whole dict: each callback reads its own keys)."""

    def on_batch_end(self, host: Any, metrics: dict[str, float]) -> None:
        """After each update; ``metrics`` is about to be logged at the run's frames (add to it)."""

    def state_dict(self) -> dict[str, Any]:
        """The entries this callback adds to every checkpoint (top-level keys)."""
        return {}

    def on_save(self, run_dir: Path) -> None:
        """After a checkpoint is written (files that go with it)."""

    def close(self) -> None:
        """However the run ends."""
