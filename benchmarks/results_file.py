"""Record one benchmark figure in docs/benchmarks/results.json and re-render its page's table.

Why: a figure in the tables at the top of docs/benchmarks/ should be one a command produced, not one
copied by hand. A benchmark script given ``--record PAGE/ID`` (an ``id`` of a row in the file; list
them with ``python benchmarks/results_table.py --ids``) composes the row's ``measured`` text from
the figures it printed and calls ``record``, which fills in the date, the machine and the command
line, writes the file and rewrites that page's table (``results_table.py --write`` for one page).

The row keeps its target and its section: what the figure is measured against, and where the page
tells its story, are for a person to write. ``record`` marks the row ``"recorded": true`` and drops
its ``"historical"`` mark (a figure once copied by hand): the table then shows it without
"(historical)".
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import shlex
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_table, also when loaded by path
import results_table

CPUINFO = Path("/proc/cpuinfo")


def cpu_model(cpuinfo: Path = CPUINFO) -> str:
    """The first ``model name`` of /proc/cpuinfo without its trade marks; "unknown CPU" without one
    (another OS, or an ARM kernel that does not name it)."""
    try:
        text = cpuinfo.read_text()
    except OSError:
        return "unknown CPU"
    found = re.search(r"^model name\s*:\s*(.+)$", text, re.M)
    if not found:
        return "unknown CPU"
    model = re.sub(r"\((R|TM|tm|r)\)", "", found[1])
    return " ".join(model.split())


def machine(load: str | None = None, cpuinfo: Path = CPUINFO, cores: int | None = None) -> str:
    """A short description of this machine for the ``machine`` column: the CPU model and the core
    count, then ``load`` ("alone", "shared") when the caller knows it; the file cannot tell."""
    text = f"{cpu_model(cpuinfo)}, {cores or os.cpu_count()} cores"
    return f"{text}, {load}" if load else text


def script_command(argv: list[str] | None = None) -> str:
    """The command line that ran this script, as a reader would type it from the checkout's root:
    ``python benchmarks/<script> <arguments>``, shell-quoted."""
    argv = sys.argv if argv is None else argv
    return shlex.join(["python", f"benchmarks/{Path(argv[0]).name}", *argv[1:]])


def find_row(pages: dict[str, list[dict]], page: str, row_id: str) -> dict:
    """The row ``row_id`` of ``page``; a ``ValueError`` naming the ones that exist otherwise."""
    if page not in pages:
        raise ValueError(f"no page {page!r} in results.json; pages: {', '.join(pages)}")
    for row in pages[page]:
        if row.get("id") == row_id:
            return row
    ids = ", ".join(str(r.get("id")) for r in pages[page])
    raise ValueError(f"no row {row_id!r} on page {page!r} of results.json; its rows: {ids}")


def row_spec(text: str, results: Path = results_table.RESULTS) -> tuple[str, str]:
    """``PAGE/ID`` checked against the file, for argparse's ``type=``: a script refuses an unknown
    row when it starts, not after its minutes of measuring."""
    page, slash, row_id = text.partition("/")
    if not slash or not page or not row_id:
        raise argparse.ArgumentTypeError(f"expected PAGE/ID (e.g. learning/ppo-5min), got {text!r}")
    try:
        find_row(results_table.load(results), page, row_id)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return page, row_id


def met_of(flags: list[bool]) -> str:
    """The ``met`` column for one check per seed (or per case): "met, 3 of 3", "met on 2 of 3",
    "missed, 3 of 3"; "met" or "missed" for a single one."""
    n, k = len(flags), sum(flags)
    if n == 1:
        return "met" if k else "missed"
    if k == n:
        return f"met, {n} of {n}"
    return f"missed, {n} of {n}" if k == 0 else f"met on {k} of {n}"


def record(
    page: str,
    row_id: str,
    measured: str,
    met: str,
    command: list[str] | None = None,
    *,
    load: str | None = None,
    results: Path = results_table.RESULTS,
    folder: Path = results_table.PAGES,
    today: datetime.date | None = None,
) -> dict:
    """Write one row's figure (``measured``, ``met``), today's date, this machine and the command
    (default: this script's own command line) into ``results``, marked recorded, then rewrite
    ``page``'s table in ``folder``. Returns the row as written."""
    if load is not None and load not in results_table.LOADS:
        raise ValueError(f"load {load!r}: one of {results_table.LOADS} or None")
    data = json.loads(results.read_text())
    row = find_row(data["pages"], page, row_id)
    row.update(
        {
            "measured": measured,
            "date": (today or datetime.date.today()).isoformat(),
            "machine": machine(load),
            "command": list(command) if command is not None else [script_command()],
            "met": met,
            "recorded": True,
        }
    )
    row.pop("command_note", None)  # a note on the old command ("arguments not recorded")
    row.pop("historical", None)  # the figure is no longer one copied by hand
    results_table.render([row])  # refuses a '|' or a line break before anything is written
    results.write_text(json.dumps(data, indent=1) + "\n")
    results_table.write({page: data["pages"][page]}, folder)
    print(f"recorded {page}/{row_id}: {measured} ({met})")
    return row


def add_options(parser: argparse.ArgumentParser) -> None:
    """``--record PAGE/ID`` and ``--record-load`` for a benchmark script's parser."""
    parser.add_argument(
        "--record",
        type=row_spec,
        metavar="PAGE/ID",
        help="write this run's figure into docs/benchmarks/results.json's row ID of PAGE "
        "and re-render that page's table (python benchmarks/results_table.py --ids)",
    )
    parser.add_argument(
        "--record-load",
        choices=results_table.LOADS,
        help="with --record: whether the machine ran nothing else (the machine column)",
    )
