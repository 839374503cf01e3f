"""Run logging: TensorBoard scalars (x axis = env frames), a console progress line, a text log.

Uses torch's ``SummaryWriter`` directly rather than TorchRL's ``TensorboardLogger`` for its
``purge_step``: a resumed run appends to the same event directory and drops any events written
after the checkpoint it resumes from, so the curves continue unbroken.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from rlgrasp.train.rundir import TEXT_LOG

log = logging.getLogger("rlgrasp.train")


def setup_text_log(run_dir: Path, name: str = TEXT_LOG) -> None:
    """Log to ``run_dir/train.log`` unless a handler (e.g. Hydra's) already writes that file."""
    target = (run_dir / name).resolve()
    root = logging.getLogger()
    for h in root.handlers + log.handlers:
        if isinstance(h, logging.FileHandler) and Path(h.baseFilename).resolve() == target:
            return
    run_dir.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(target)
    handler.setFormatter(logging.Formatter("[%(asctime)s][%(name)s][%(levelname)s] - %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    if not root.handlers:  # outside Hydra: also print to the console
        logging.basicConfig(level=logging.INFO, format="[%(asctime)s][%(levelname)s] %(message)s")


class RunLogger:
    """TensorBoard writer (or nothing, with ``backend="none"``)."""

    def __init__(self, log_dir: Path, backend: str, purge_step: int | None = None) -> None:
        self.writer = None
        if backend == "tensorboard":
            self.writer = SummaryWriter(str(log_dir), purge_step=purge_step)
        elif backend != "none":
            raise ValueError(f"logger.backend must be 'tensorboard' or 'none', got {backend!r}")

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        if self.writer is None:
            return
        for tag, value in metrics.items():
            if value is not None and not (isinstance(value, float) and math.isnan(value)):
                self.writer.add_scalar(tag, value, step)

    def text(self, tag: str, text: str, step: int = 0) -> None:
        if self.writer is not None:
            # Markdown code block keeps the YAML's indentation in TensorBoard's text tab.
            self.writer.add_text(tag, "```\n" + text + "\n```", step)

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        """``hparams`` flat (``a.b.c`` keys); values TensorBoard cannot show (lists, None) as text."""
        if self.writer is not None:
            shown = {k: v if isinstance(v, (bool, int, float, str)) else str(v) for k, v in hparams.items()}
            clean = {k: v for k, v in metrics.items() if not math.isnan(v)}
            self.writer.add_hparams(shown, clean, run_name=".")

    def flush(self) -> None:
        if self.writer is not None:
            self.writer.flush()

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def progress_line(
    frames: int,
    total: int,
    sps: float,
    success: float | None,
    ret: float | None,
    eval_success: float | None,
    eta_s: float,
) -> str:
    """``frames 12,800/100,000 [###-------]  13% | SPS 2,345 | ... | ETA 0:01:23``."""
    frac = min(frames / total, 1.0) if total > 0 else 0.0
    bar = "#" * int(frac * 20) + "-" * (20 - int(frac * 20))
    parts = [f"frames {frames:,}/{total:,} [{bar}] {frac:4.0%}", f"SPS {sps:,.0f}"]
    if ret is not None:
        parts.append(f"return {ret:.2f}")
    if success is not None:
        parts.append(f"success {success:.2f}")
    if eval_success is not None:
        parts.append(f"eval {eval_success:.2f}")
    eta = int(eta_s) if math.isfinite(eta_s) else 0
    parts.append(f"ETA {eta // 3600}:{eta % 3600 // 60:02d}:{eta % 60:02d}")
    return " | ".join(parts)
