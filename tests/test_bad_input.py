"""Bad input to ``scripts/train.py``: each gives one line naming the key or file, no traceback, and
leaves no run directory behind. The cases run the real entry point (Hydra included) in-process.

``python tests/test_bad_input.py`` prints the table of docs/FAULTS.md from these cases.
"""

from __future__ import annotations

import pickle
import runpy
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ["experiment=smoke", "logger=none"]


def _make_run(root: Path) -> Path:
    """A run directory holding one real smoke checkpoint (built without starting workers)."""
    from rlgrasp.compose import compose_train
    from rlgrasp.train.loop import Trainer

    run = root / "outputs" / "train" / "smoke" / "done_run"
    if not (run / "checkpoints" / "last.pt").exists():
        Trainer(compose_train([*SMOKE, f"paths.output_dir={run}"])).save()
    return run


def _files(root: Path) -> dict[str, str]:
    """Inputs that are files: a run, an empty dir, a truncated checkpoint, a foreign pickle."""
    run = _make_run(root)
    empty = root / "empty_run"
    empty.mkdir(exist_ok=True)
    truncated = root / "truncated.pt"
    data = (run / "checkpoints" / "last.pt").read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    foreign = root / "foreign.pt"
    foreign.write_bytes(pickle.dumps({"weights": [1, 2, 3]}))
    unwritable = root / "a_file"
    unwritable.write_text("not a directory")
    return {"run": str(run), "empty": str(empty), "truncated": str(truncated), "foreign": str(foreign),
            "unwritable": str(unwritable / "out")}


# (what, overrides (with {run} etc. filled from _files), a fragment of the one-line message)
CASES = [
    ("unknown key", ["algo.lrr=1"], "Could not override 'algo.lrr'"),
    ("wrong type", ["algo.lr=abc"], "algo.lr"),
    ("unknown group option", ["collector=bogus"], "Could not find 'collector/bogus'"),
    ("no frames", ["total_frames=0"], "total_frames=0: must be > 0"),
    ("negative frames", ["total_frames=-5"], "total_frames=-5: must be > 0"),
    ("negative workers", ["collector.num_workers=-1"], "collector.num_workers=-1: must be >= 0"),
    ("no envs per worker", ["collector.envs_per_worker=0"], "collector.envs_per_worker=0: must be >= 1"),
    ("minibatch larger than a batch", ["algo.minibatch_size=4096"],
     "algo.minibatch_size=4096: must be between 1"),
    ("minibatch 0", ["algo.minibatch_size=0"], "algo.minibatch_size=0: must be between 1"),
    ("no epochs", ["algo.epochs=0"], "algo.epochs=0: must be >= 1"),
    ("zero learning rate", ["algo.lr=0"], "algo.lr=0.0: must be > 0"),
    ("negative learning rate", ["algo.lr=-0.001"], "algo.lr=-0.001: must be > 0"),
    ("no substeps", ["env.substeps=0"], "env: substeps must be a positive integer, got 0"),
    ("unknown control mode", ["env.control_mode=fly"], "env:"),
    ("no hidden layers", ["model.hidden_sizes=[]"], "model.hidden_sizes=[]: must be a non-empty list"),
    ("inverted randomization range", ["env.randomization={object_mass:[1.0,0.5]}"],
     "'object_mass': low (1.0) is greater than high (0.5)"),
    ("negative randomization range", ["env.randomization={object_mass:[-1.0,0.5]}"],
     "'object_mass': range [-1.0, 0.5] is outside the allowed"),
    ("CUDA on a machine without it", ["device=cuda"], "device='cuda': CUDA is not available"),
    ("no eval episodes", ["eval.episodes=0"], "eval.episodes=0: must be >= 1"),
    ("keep no checkpoints", ["checkpoint.keep_last=0"], "checkpoint.keep_last=0: must be >= 1"),
    ("resume a missing path", ["resume={root}/nowhere"], "nowhere: no such file or directory"),
    ("resume a directory without checkpoints", ["resume={empty}"], "no checkpoints:"),
    ("resume a truncated checkpoint", ["resume={truncated}"], "unreadable checkpoint:"),
    ("resume a file that is not a checkpoint", ["resume={foreign}"], "unreadable checkpoint:"),
    ("resume with another model", ["resume={run}", "model.hidden_sizes=[32]"],
     "cannot change on resume: model.hidden_sizes: the checkpoint has [64, 64], the command line [32]"),
    ("resume with another algorithm setting", ["resume={run}", "algo.gamma=0.5"],
     "cannot change on resume: algo.gamma"),
    ("a fresh run into a run dir with checkpoints", ["hydra.run.dir={run}"], "already holds checkpoints"),
    ("an unwritable output directory", ["hydra.run.dir={unwritable}"], "cannot create the run directory"),
]


def _fill(overrides: list[str], root: Path, paths: dict[str, str]) -> list[str]:
    out = []
    for o in overrides:
        for name, value in {"root": str(root), **paths}.items():
            o = o.replace("{" + name + "}", value)
        out.append(o)
    return out


def run_train(argv: list[str], cwd: Path, capsys) -> tuple[int, str]:
    """``scripts/train.py argv`` in this process: (exit code, everything printed)."""
    import logging

    from hydra.core.global_hydra import GlobalHydra

    old_argv, old_cwd = sys.argv, Path.cwd()
    sys.argv = [str(ROOT / "scripts" / "train.py"), *argv]
    code = 0
    import os

    os.chdir(cwd)
    try:
        runpy.run_path(str(ROOT / "scripts" / "train.py"), run_name="__main__")
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    finally:
        sys.argv = old_argv
        os.chdir(old_cwd)
        GlobalHydra.instance().clear()
        for handler in logging.getLogger().handlers[:]:
            logging.getLogger().removeHandler(handler)
    out = capsys.readouterr()
    return code, out.out + out.err


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    root = tmp_path_factory.mktemp("bad_input")
    return root, _files(root)


@pytest.mark.parametrize(("what", "overrides", "message"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_gives_one_line_and_leaves_nothing(files, capsys, what, overrides, message) -> None:
    root, paths = files
    argv = _fill([*SMOKE, *overrides], root, paths)
    before = sorted(p for p in root.rglob("*") if "done_run" not in p.parts)
    code, out = run_train([*argv, f"paths.root_dir={root}"], root, capsys)
    assert code != 0, out
    assert "Traceback" not in out, out
    assert message in out, out
    after = sorted(p for p in root.rglob("*") if "done_run" not in p.parts)
    assert after == before, f"left behind: {set(after) - set(before)}"
    # the run that inputs pointed at is untouched
    assert sorted(p.name for p in (Path(paths["run"]) / "checkpoints").iterdir()) == [
        "ckpt_0000000000.pt", "last.pt"]


def _table() -> str:
    """The docs/FAULTS.md table: each case and the line it prints (run: python tests/test_bad_input.py)."""
    import tempfile

    from rlgrasp.utils import markdown_table

    class _Capture:
        def readouterr(self):
            return type("O", (), {"out": "", "err": ""})

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        paths = _files(root)
        for what, overrides, _ in CASES:
            argv = _fill([*SMOKE, *overrides], root, paths)
            import contextlib
            import io

            buf = io.StringIO()
            with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
                code, _ = run_train([*argv, f"paths.root_dir={root}"], root, _Capture())
            lines = [ln for ln in buf.getvalue().splitlines()
                     if ln.strip() and not ln.startswith(("argv", "Set the environment"))]
            errors = [ln for ln in lines if "ERROR" in ln] or lines
            line = errors[0].split(" - ", 1)[-1]
            shown = " ".join(overrides).replace(tmp, "...")
            rows.append((what, f"`{shown}`", code, line.replace(tmp, "...").replace("|", "\\|")))
    return markdown_table(["input", "command line (after `experiment=smoke`)", "exit", "message"], rows)


if __name__ == "__main__":
    print(_table())
