"""Where a training run lives: the run directory's name and layout, the Hydra files of each start,
and what a refused start takes back.

A run directory is ``outputs/train/<experiment>/<date>_<time>_s<seed>_<random>/`` holding
``.hydra/`` (the launch's composed config; each later start's in ``.hydra/resume_<n>/``),
``checkpoints/``, ``tensorboard/``, ``env_errors/`` and ``train.log``. Hydra names it through the
``rlgrasp_run_dir`` resolver of ``configs/hydra/default.yaml``; ``resume=`` chooses an existing one.
What a start continues from once it is there (which checkpoint, which config) is
``rlgrasp.train.resume``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import secrets
import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

#: The layout of a run directory (``rlgrasp.train.loop.Trainer`` writes it).
CHECKPOINTS = "checkpoints"
TENSORBOARD = "tensorboard"
ENV_ERRORS = "env_errors"
TEXT_LOG = "train.log"

#: Run directories this process chose that did not exist before (safe to remove on a start-up error),
#: each with the outermost of its parents that did not exist either (a new experiment's folder).
FRESH_RUN_DIRS: dict[str, Path] = {}
_RUN_TOKEN = secrets.token_hex(3)  # one per process: every resolution of hydra.run.dir agrees
#: ``hydra.output_subdir`` per run directory, chosen once per Hydra run (Hydra resolves it more than
#: once, the last time after writing into it); ``RunDirCheck.on_run_start`` forgets earlier runs'.
_OUTPUT_SUBDIRS: dict[str, str] = {}


def run_dir(resume: str | None, base: str, seed: int) -> str:
    """``hydra.run.dir``: a run directory named ``<date>_<time>_s<seed>_<random>`` under ``base``
    (two runs started in the same second never share one); ``resume=<run dir>`` that directory,
    ``resume=<run>/checkpoints/<file>.pt`` its run (any other resume: a new directory);
    ``resume=auto`` the newest run of ``base`` with this seed that holds a checkpoint, else a new one."""
    chosen = None
    if resume == "auto":
        runs = sorted(Path(base).glob(f"*_s{seed}_*/{CHECKPOINTS}/*.pt"), key=lambda p: p.parts[-3])
        chosen = str(runs[-1].parents[1]) if runs else None
    elif resume:  # a run, or a file in a run's checkpoints/; anything else fails later, in a new dir
        path = Path(resume)
        if path.is_dir() and any((path / CHECKPOINTS).glob("*.pt")):
            chosen = str(path)
        elif path.is_file() and path.parent.name == CHECKPOINTS:
            chosen = str(path.parents[1])
    if chosen is None:
        chosen = f"{base}/{time.strftime('%Y-%m-%d_%H-%M-%S')}_s{seed}_{_RUN_TOKEN}"
    path = Path(chosen).resolve()
    if not path.exists():
        outermost = path
        while not outermost.parent.exists():
            outermost = outermost.parent
        FRESH_RUN_DIRS[str(path)] = outermost
    return chosen


def output_subdir(output_dir: str) -> str:
    """``hydra.output_subdir``: ``.hydra`` for the first start in a run directory; every later start
    there (a resume, a requeued job) ``.hydra/resume_<n>`` (n = 1, 2, ...). Hydra writes config.yaml,
    hydra.yaml and overrides.yaml into it: in ``.hydra/`` itself a resume would overwrite the launch's."""
    key = str(Path(output_dir).resolve())
    if key not in _OUTPUT_SUBDIRS:
        hydra_dir = Path(key) / ".hydra"
        n = 0
        if (hydra_dir / "config.yaml").exists():
            n = 1
            while (hydra_dir / f"resume_{n}").exists():
                n += 1
        _OUTPUT_SUBDIRS[key] = f".hydra/resume_{n}" if n else ".hydra"
    return _OUTPUT_SUBDIRS[key]


def name_problem(key: str, value: object) -> str | None:
    """Why ``value`` cannot name one folder (``None``: it can). Names become one path component
    under an output root (``outputs/train/<experiment_name>``, a sweep's ``<root_dir>/<study_name>``,
    an evaluation's ``eval/<name>``): ``../x`` or ``/tmp/x`` would put the files somewhere else,
    where no reader (resume=auto, a sweep's summary, rlgrasp-report) looks for them."""
    text = str(value)
    if text in ("", ".", "..") or "/" in text or "\\" in text or "\0" in text:
        return f"{key}={text!r}: must be one folder name (no '/', '..' or absolute path)"
    return None


def register_resolvers() -> None:
    """``rlgrasp_run_dir`` and ``rlgrasp_output_subdir``, which ``configs/hydra/default.yaml`` calls."""
    if not OmegaConf.has_resolver("rlgrasp_run_dir"):
        OmegaConf.register_new_resolver("rlgrasp_run_dir", run_dir)
    if not OmegaConf.has_resolver("rlgrasp_output_subdir"):
        OmegaConf.register_new_resolver("rlgrasp_output_subdir", output_subdir)


def remove_refused_start(path: Path) -> None:
    """After a refused start: remove the run directory if this process created it and it holds only
    Hydra's files and the log; in an existing run, the ``.hydra/resume_<n>`` Hydra just wrote."""
    if not path.is_dir():
        return
    key = str(path.resolve())
    if key in FRESH_RUN_DIRS:
        if {p.name for p in path.iterdir()} <= {".hydra", TEXT_LOG}:
            logging.shutdown()  # closes train.log before its directory goes
            shutil.rmtree(path, ignore_errors=True)
            _remove_empty_parents(Path(key), FRESH_RUN_DIRS[key])
        return
    subdir = HydraConfig.get().output_subdir if HydraConfig.initialized() else None
    if subdir and subdir.startswith(".hydra/resume_"):
        shutil.rmtree(path / subdir, ignore_errors=True)


def _remove_empty_parents(run: Path, outermost: Path) -> None:
    """The folders this process created above a removed run directory, while they are empty."""
    folder = run.parent
    while outermost != run and (folder == outermost or outermost in folder.parents):
        try:
            folder.rmdir()  # only an empty folder: a run started beside it in the meantime stays
        except OSError:
            return
        folder = folder.parent


class RunDirCheck(Callback):
    """Hydra callback (``configs/hydra/default.yaml``): an output directory that cannot be created
    ends the command with one line instead of Hydra's traceback from inside its job runner."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        _OUTPUT_SUBDIRS.clear()  # a new start in this process (tests run several): choose afresh
        self._check_name(config)
        self._check(config.hydra.run.dir)

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        self._check_name(config)
        self._check(config.hydra.sweep.dir)

    @staticmethod
    def _check_name(config: DictConfig) -> None:
        # Before Hydra creates the run directory: ``experiment_name=../x`` would create it elsewhere.
        problem = name_problem("experiment_name", config.get("experiment_name", "default"))
        if problem:
            print(f"error: {problem}", file=sys.stderr)
            sys.exit(2)

    @staticmethod
    def _check(path: Any) -> None:
        # Creates nothing: hydra.run.dir holds the time, so this resolution may name another second
        # than the one the job then creates; a directory made here would be left behind empty.
        target = Path(str(path)).absolute()
        existing = next(p for p in (target, *target.parents) if p.exists())
        problem = None
        if not existing.is_dir():
            problem = "Not a directory"
        elif not os.access(existing, os.W_OK | os.X_OK):
            problem = f"{existing} is not writable"
        if problem:
            print(f"error: cannot create the run directory {path}: {problem}", file=sys.stderr)
            sys.exit(2)


#: The lock a training process holds on its run directory while it runs.
LOCK_FILE = ".lock"


@contextlib.contextmanager
def run_lock(run_dir: Path) -> Iterator[None]:
    """Hold ``<run_dir>/.lock`` while training: a second process on the same run (two
    ``resume=auto`` started at once) is refused in one line instead of interleaving its checkpoints
    with the first's. The lock is the kernel's (``flock``): it goes with the process, however that ends."""
    import fcntl  # POSIX; rlgrasp's training runs on Linux and macOS

    handle = open(Path(run_dir) / LOCK_FILE, "a+")  # noqa: SIM115 - held for the run, closed below
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another process"
            raise RunLockedError(
                f"{run_dir} is being trained by {holder}: one process per run directory (wait for it, "
                "or start this run elsewhere)"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"pid {os.getpid()}")
        handle.flush()
        yield
    finally:
        handle.close()


class RunLockedError(RuntimeError):
    """Another process holds the run directory's lock; the message says which."""
