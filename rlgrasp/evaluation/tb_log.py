"""Log an evaluation into its run's TensorBoard: scalars at the checkpoint's frame count, video frames.

``SummaryWriter.add_video`` needs moviepy (not installed, and not worth a dependency): each video
episode is logged as one image, a strip of evenly spaced frames, under ``eval_video/``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rlgrasp.evaluation.episodes import EpisodeResult
from rlgrasp.evaluation.video import contact_sheet, outcome_caption


def log_to_tensorboard(
    run_dir: str | Path, name: str, metrics: dict[str, Any], videos: Sequence[EpisodeResult], step: int
) -> Path:
    """Write into ``<run dir>/tensorboard`` (a new events file; tags distinct from training's)."""
    # Lazy: tensorboard's writer, which only an evaluation logged to its run's TensorBoard needs.
    from torch.utils.tensorboard import SummaryWriter

    log_dir = Path(run_dir) / "tensorboard"
    writer = SummaryWriter(log_dir=str(log_dir))
    try:
        prefix = f"posthoc_eval/{name}"
        writer.add_scalar(f"{prefix}/success_at_end", metrics["success_at_end"]["rate"], step)
        writer.add_scalar(f"{prefix}/success_once", metrics["success_once"]["rate"], step)
        writer.add_scalar(f"{prefix}/return_mean", metrics["return"]["mean"], step)
        if metrics.get("teacher"):  # a camera policy's teacher on the same episodes
            teacher = metrics["teacher"]["success_at_end"]["rate"]
            writer.add_scalar(f"{prefix}/teacher_success_at_end", teacher, step)
        writer.add_text(f"{prefix}/summary", metrics.get("summary_markdown", ""), step)
        for r in videos:
            if r.frames:
                writer.add_image(
                    f"eval_video/{name}/seed_{r.seed}", contact_sheet(r.frames), step, dataformats="HWC"
                )
                writer.add_text(f"eval_video/{name}/seed_{r.seed}", outcome_caption(r), step)
    finally:
        writer.close()
    return log_dir
