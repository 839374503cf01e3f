"""Run logging: the loggers ``logger._target_`` names (console only, TensorBoard; the trackers are
in ``rlgrasp.train.tracking.trackers``), the console's progress line and the text log.

Uses torch's ``SummaryWriter`` directly rather than TorchRL's ``TensorboardLogger`` for its
``purge_step``: a resumed run appends to the same event directory and drops any events written
after the checkpoint it resumes from, so the curves continue unbroken.
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from rlgrasp.logger_schema import LoggerConfig, MlflowLoggerConfig, WandbLoggerConfig  # noqa: F401
from rlgrasp.rundir import TENSORBOARD, TEXT_LOG

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


def final_metrics(result: dict[str, float]) -> dict[str, float]:
    """The final evaluation as the hparams table's metrics (NaN where the env reports none)."""
    return {
        "hparam/eval_success_rate": float(result.get("success_rate", float("nan"))),
        "hparam/eval_mean_reward": result.get("mean_reward", float("nan")),
    }


class ConsoleLogger:
    """``logger=none``: the progress line on the console (and in ``train.log``), no curves; the base
    of every logger.

    The Trainer builds the ``logger`` node's class with the run's own arguments besides the node's
    keys: ``run_dir``, the resolved ``config`` and ``resumed_frames`` (the checkpoint's frames on a
    resume, else None). The calls it makes: ``scalars``, ``text``, ``hparams``, ``progress``,
    ``flush``, ``close``.
    """

    def __init__(
        self,
        run_dir: Path,
        config: dict[str, Any],
        resumed_frames: int | None,
        console_interval_s: float = 5.0,
    ) -> None:
        self.console_interval_s = console_interval_s
        self._last_progress = time.monotonic()

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        pass

    def text(self, tag: str, text: str, step: int = 0) -> None:
        pass

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        pass

    def progress(self, line: str) -> None:
        """Log ``line`` if ``console_interval_s`` has passed since the last one (then flush too)."""
        now = time.monotonic()
        if now - self._last_progress >= self.console_interval_s:
            self._last_progress = now
            log.info(line)
            self.flush()

    def flush(self) -> None:
        pass

    def close(self) -> None:
        pass


class TensorBoardLogger(ConsoleLogger):
    """``logger=tensorboard``: the scalars (x axis = env frames), the config and the hparams in
    ``<run dir>/tensorboard``; a resumed run drops the events after its checkpoint (``purge_step``)."""

    def __init__(
        self,
        run_dir: Path,
        config: dict[str, Any],
        resumed_frames: int | None,
        console_interval_s: float = 5.0,
    ) -> None:
        super().__init__(run_dir, config, resumed_frames, console_interval_s)
        purge_step = None if resumed_frames is None else resumed_frames + 1
        self.writer = SummaryWriter(str(Path(run_dir) / TENSORBOARD), purge_step=purge_step)

    def scalars(self, metrics: dict[str, float], step: int) -> None:
        for tag, value in metrics.items():
            if value is not None and not (isinstance(value, float) and math.isnan(value)):
                self.writer.add_scalar(tag, value, step)

    def text(self, tag: str, text: str, step: int = 0) -> None:
        # Markdown code block keeps the YAML's indentation in TensorBoard's text tab.
        self.writer.add_text(tag, "```\n" + text + "\n```", step)

    def hparams(self, hparams: dict[str, Any], metrics: dict[str, float]) -> None:
        """``hparams`` flat (``a.b.c`` keys); values TensorBoard cannot show (lists, None) as text."""
        shown = {k: v if isinstance(v, (bool, int, float, str)) else str(v) for k, v in hparams.items()}
        clean = {k: v for k, v in metrics.items() if not math.isnan(v)}
        self.writer.add_hparams(shown, clean, run_name=".")

    def flush(self) -> None:
        self.writer.flush()

    def close(self) -> None:
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
    eta = max(int(eta_s), 0) if math.isfinite(eta_s) else 0  # a spent time budget: 0, not negative
    parts.append(f"ETA {eta // 3600}:{eta % 3600 // 60:02d}:{eta % 60:02d}")
    return " | ".join(parts)
