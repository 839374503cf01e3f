"""A replay buffer on disk, beside the checkpoints: each checkpoint adds one file holding the
transitions stored since the one before, and a resumed run reads them back in the order they came.

Writing the whole buffer at every checkpoint wrote each transition several times over, and cost a
camera run a share of its time budget (docs/algorithms.md, "Collecting between the updates, and a
checkpoint that writes each frame once"); here each transition is written once. Read back in order
into a ring buffer, the newest frames are kept and the oldest are the next overwritten, as they
were before the run stopped.

Each file is a ``torch.save``d dict of plain tensors, read with ``weights_only=True``, named
``<sequence>_<frames>.pt`` in ``<run>/replay/``. A run written before these files (one
``replay.pt``, the whole buffer) is read first and removed once the files cover the buffer.

A checkpoint names the sequence number of the newest file it goes with, and that file is written
before the checkpoint: a run killed between the two resumes from the checkpoint before, whose files
are all there, and the newer file (transitions that checkpoint never saw) is removed, as is a
``.tmp`` left by a write cut short.

The folder may have come with a run someone sent: nothing in it is read, written or removed through
a symlink (the folder itself a link would move the removals above outside the run), and a file cut
short or holding NaN is refused in one line (``ReplayError``) before the buffer is filled.
"""

from __future__ import annotations

import pickle
import re
from collections.abc import Iterator
from pathlib import Path

import torch
from tensordict import TensorDict, TensorDictBase

from rlgrasp.config import ConfigError
from rlgrasp.received import ReceivedError, check_finite, check_inside, check_tree

REPLAY_DIR = "replay"
#: The whole buffer in one file, as runs wrote it before ``REPLAY_DIR``: still read.
LEGACY_FILE = "replay.pt"
_CHUNK = re.compile(r"^(\d+)_(\d+)\.pt$")


class ReplayError(ConfigError):
    """A replay folder or file that cannot be used; the message is one line and names it."""


class ReplayFiles:
    """The replay files of one run directory."""

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        self.folder = self.run_dir / REPLAY_DIR
        self.legacy = self.run_dir / LEGACY_FILE

    def _check_links(self) -> None:
        """No link on the way: a removal or a write here must stay inside the run directory."""
        try:
            for path in (self.folder, self.legacy):
                check_inside(self.run_dir, path, f"replay of {self.run_dir}")
            check_tree(self.folder, f"replay of {self.run_dir}")
        except ReceivedError as exc:
            raise ReplayError(str(exc)) from None

    def chunks(self) -> list[tuple[int, int, Path]]:
        """``(sequence, frames, path)`` of each file, oldest first; other names are not ours."""
        self._check_links()
        if not self.folder.is_dir():
            return []
        found = [(_CHUNK.match(p.name), p) for p in self.folder.iterdir()]
        return sorted((int(m[1]), int(m[2]), p) for m, p in found if m)

    def exist(self) -> bool:
        """Whether the run has any replay file to read."""
        self._check_links()
        return self.legacy.is_file() or bool(self.chunks())

    def write(self, transitions: TensorDictBase) -> int:
        """One more file with ``transitions`` (oldest first), written atomically; its sequence number."""
        chunks = self.chunks()
        sequence = chunks[-1][0] + 1 if chunks else 1
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"{sequence:06d}_{transitions.shape[0]}.pt"
        tmp = path.with_name(f".{path.name}.tmp")
        torch.save({"frames": transitions.shape[0], "data": transitions.to("cpu").to_dict()}, tmp)
        tmp.replace(path)
        return sequence

    def prune(self, keep_frames: int) -> None:
        """Remove the files older than the newest ones that hold ``keep_frames`` transitions (the
        buffer's size: what reading would overwrite anyway)."""
        held = 0
        for _, frames, path in reversed(self.chunks()):
            if held >= keep_frames:
                path.unlink()
            held += frames
        if held >= keep_frames:
            self.legacy.unlink(missing_ok=True)

    def discard_after(self, sequence: int) -> list[Path]:
        """Remove the files newer than ``sequence`` (written for a checkpoint that never was, or
        one newer than the checkpoint a run resumes from) and any temporary file a cut-short write
        left; the paths removed."""
        gone = [p for seq, _, p in self.chunks() if seq > sequence]
        gone += self._temporary()
        for path in gone:
            path.unlink()
        return gone

    def clear(self) -> None:
        """Remove every replay file: a new run's first checkpoint must not leave an older run's
        transitions for its resume to read."""
        for _, _, path in self.chunks():
            path.unlink()
        for path in self._temporary():
            path.unlink()
        self.legacy.unlink(missing_ok=True)

    def _temporary(self) -> list[Path]:
        """Files a write cut short left (``write`` names them ``.<name>.tmp``)."""
        self._check_links()
        return list(self.folder.glob(".*.tmp")) if self.folder.is_dir() else []

    def read(self) -> Iterator[TensorDict]:
        """Each file's transitions, oldest first (a legacy ``replay.pt`` before them)."""
        paths = [self.legacy] if self.legacy.is_file() else []
        for path in [*paths, *(p for _, _, p in self.chunks())]:
            yield _read(path)


def _read(path: Path) -> TensorDict:
    """One file's transitions; a file cut short, of another shape, or holding NaN in one line."""
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        data = TensorDict(saved["data"], batch_size=[saved["frames"]])
    except (OSError, RuntimeError, EOFError, ValueError, KeyError, TypeError, pickle.UnpicklingError) as exc:
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise ReplayError(f"unreadable replay file {path} ({type(exc).__name__}: {reason})") from None
    try:
        for key, tensor in data.items(True, True):
            check_finite(tensor, f"{path.name}: {key}", "replay")
    except ReceivedError as exc:
        raise ReplayError(str(exc)) from None
    return data
