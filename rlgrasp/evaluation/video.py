"""Videos of evaluation episodes with the outcome written on every frame.

GIF through matplotlib's ``PillowWriter`` (Pillow ships with matplotlib); MP4 only when an
``ffmpeg`` binary exists. The caption carries the final outcome, so a thumbnail already tells
success from failure, and the current step's success flag.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from rlgrasp.evaluation.episodes import EpisodeResult
from rlgrasp.utils import pyplot


def outcome_caption(r: EpisodeResult) -> str:
    if r.success_at_end:
        return f"SUCCESS (lifted at step {r.first_success_step}, held to the end)"
    if r.success_once:
        return f"FAILURE at end (lifted at step {r.first_success_step}, then lost)"
    return "FAILURE (object never lifted)" + (" - grasped" if r.grasped_at_end else "")


def video_format(requested: str = "auto") -> str:
    """``gif``, or ``mp4`` when asked for (or ``auto``) and ffmpeg is installed."""
    if requested not in ("auto", "gif", "mp4"):
        raise ValueError(f"video_format={requested}: must be auto, gif or mp4")
    has_ffmpeg = shutil.which("ffmpeg") is not None
    if requested == "mp4" and not has_ffmpeg:
        raise ValueError("video_format=mp4 needs an ffmpeg binary on PATH; use video_format=gif")
    if requested == "auto":
        return "mp4" if has_ffmpeg else "gif"
    return requested


def write_video(r: EpisodeResult, path: Path, fps: int = 20, fmt: str = "gif") -> Path:
    """Render ``r.frames`` with a caption: the outcome (coloured) on top, step and flag below."""
    # Lazy: matplotlib, which only the videos need (rlgrasp.utils.pyplot is lazy for the same reason).
    from matplotlib.animation import FFMpegWriter, PillowWriter

    plt = pyplot()

    if not r.frames:
        raise ValueError(f"episode {r.index} has no frames (was it rendered?)")
    h, w = r.frames[0].shape[:2]
    fig = plt.figure(figsize=(w / 80, h / 80 + 0.6), dpi=80)
    ax = fig.add_axes((0, 0.6 / (h / 80 + 0.6) * 0.5, 1, h / (h + 48)))
    ax.axis("off")
    image = ax.imshow(r.frames[0])
    colour = "tab:green" if r.success_at_end else "tab:red"
    fig.text(
        0.5,
        0.98,
        f"seed {r.seed}: {outcome_caption(r)}",
        ha="center",
        va="top",
        fontsize=8,
        color="white",
        bbox={"facecolor": colour, "edgecolor": "none", "pad": 2},
    )
    status = fig.text(0.02, 0.01, "", ha="left", va="bottom", fontsize=8)
    writer = FFMpegWriter(fps=fps) if fmt == "mp4" else PillowWriter(fps=fps)
    path = path.with_suffix(f".{fmt}")
    total = len(r.frames) - 1
    with writer.saving(fig, str(path), dpi=80):
        for t, frame in enumerate(r.frames):
            image.set_data(frame)
            lifted = t > 0 and r.step_success[t - 1]
            status.set_text(f"step {t}/{total}   object lifted now: {'yes' if lifted else 'no'}")
            status.set_color("tab:green" if lifted else "black")
            writer.grab_frame()
    plt.close(fig)
    return path


def contact_sheet(frames: list[np.ndarray], count: int = 8) -> np.ndarray:
    """``count`` evenly spaced frames side by side (HWC uint8): a video's TensorBoard stand-in."""
    idx = np.linspace(0, len(frames) - 1, min(count, len(frames))).round().astype(int)
    return np.concatenate([frames[i] for i in idx], axis=1)
