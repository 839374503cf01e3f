"""examples/tutorial.ipynb is what jupytext makes of examples/notebook.py, committed with its outputs,
and it runs: the quick set compares the pair, the complete suite executes the notebook with nbclient
(the `notebook` extra)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "examples" / "notebook.py"
NOTEBOOK = ROOT / "examples" / "tutorial.ipynb"
RESYNC = (
    "jupytext --to ipynb examples/notebook.py -o examples/tutorial.ipynb"
    " && jupyter execute --inplace examples/tutorial.ipynb"
)


def cells(notebook: Any) -> list[tuple[str, str]]:
    return [(cell.cell_type, cell.source) for cell in notebook.cells]


def images(notebook: Any) -> int:
    """How many PNG images the notebook's code cells show."""
    return sum(
        "image/png" in output.get("data", {})
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.outputs
    )


def test_the_notebook_is_its_source_with_outputs():
    jupytext = pytest.importorskip("jupytext")
    nbformat = pytest.importorskip("nbformat")
    committed = nbformat.read(NOTEBOOK, as_version=4)
    drifted = (
        "examples/tutorial.ipynb differs from examples/notebook.py: re-sync them from the repository's root"
    )
    assert cells(committed) == cells(jupytext.read(SOURCE)), f"{drifted} with {RESYNC}"
    unrun = [
        i
        for i, cell in enumerate(committed.cells, 1)
        if cell.cell_type == "code" and cell.execution_count is None
    ]
    assert not unrun, f"examples/tutorial.ipynb cells {unrun} were not executed: {RESYNC}"
    assert images(committed) >= 3, f"examples/tutorial.ipynb holds {images(committed)} images: {RESYNC}"


def failure(notebook: Any, index: int | None, exc: BaseException) -> str:
    """One line: the cell (1-based, as a notebook's reader counts them) and the error's last line."""
    if hasattr(exc, "ename"):  # nbclient's CellExecutionError: the exception the cell raised
        last = [line for line in str(exc.evalue).splitlines() if line.strip()] or [""]
        error = f"{exc.ename}: {last[-1]}"
    else:  # a cell past the timeout (its message goes on with the cell's source), a kernel that died
        first = str(exc).strip().splitlines() or [""]
        error = f"{type(exc).__name__}: {first[0]}"
    if index is None:
        return f"examples/tutorial.ipynb did not start: {error}"
    code = notebook.cells[index].source.strip().splitlines() or [""]
    return f"examples/tutorial.ipynb cell {index + 1} ({code[0]}) failed: {error}"


@pytest.mark.full
def test_the_notebook_runs(tmp_path, monkeypatch):
    nbclient = pytest.importorskip("nbclient")
    nbformat = pytest.importorskip("nbformat")
    pytest.importorskip("ipykernel")
    # The kernel inherits this environment: rlgrasp from this checkout, files under tmp_path, and
    # matplotlib's inline backend (a MPLBACKEND such as Agg would draw no image).
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    )
    monkeypatch.setenv("RLGRASP_NOTEBOOK_OUT", str(tmp_path / "outputs"))
    monkeypatch.delenv("MPLBACKEND", raising=False)
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    running: dict[str, int] = {}

    def started(cell: Any, cell_index: int) -> None:
        running["index"] = cell_index

    client = nbclient.NotebookClient(
        notebook,
        timeout=300,
        kernel_name="python3",
        resources={"metadata": {"path": str(ROOT)}},
        on_cell_start=started,
    )
    failed = None
    try:
        client.execute()
    except Exception as exc:  # CellExecutionError, CellTimeoutError, DeadKernelError
        failed = failure(notebook, running.get("index"), exc)
    nbformat.write(notebook, tmp_path / "tutorial.ipynb")  # as it ran, to read after a failure
    if failed:
        pytest.fail(failed, pytrace=False)
    errors = [
        i + 1
        for i, cell in enumerate(notebook.cells)
        if cell.cell_type == "code" and any(o.output_type == "error" for o in cell.outputs)
    ]
    assert not errors, f"examples/tutorial.ipynb cells {errors} raised"
    assert images(notebook) >= 3, (
        f"examples/tutorial.ipynb showed {images(notebook)} images, expected 3 or more"
    )
