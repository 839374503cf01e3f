"""Render the "where each target stands" table at the top of every page of docs/benchmarks/ from
docs/benchmarks/results.json, so that a figure in those tables is one the file holds (and the file
says which command produced it).

    python benchmarks/results_table.py            # print every page's table
    python benchmarks/results_table.py --write    # rewrite the tables in the pages from the file
    python benchmarks/results_table.py --check    # exit 1 if a page's table differs from the file
    python benchmarks/results_table.py --ids      # every row's PAGE/ID, for a script's --record

A page holds its table between two comments, `<!-- results-table: NAME -->` and
`<!-- /results-table -->`, NAME being the page's key in the file. To change a figure, change the
file (with the command that produced it, and the section of the page that tells the story), then
`--write`; tests/test_results_table.py fails while the two disagree. Each row has an `id`; a
benchmark script given `--record PAGE/ID` writes its own row (benchmarks/results_file.py), and
`--ids` lists them.

The same file's `summaries` are the figures the README, docs/index.md and the guides quote: each a
label and a row (`PAGE/ID`), rendered between `<!-- results-summary: NAME -->` and
`<!-- /results-summary -->` in the files of `SUMMARY_FILES`, so that a figure is typed once. No cell
holds more than `MAX_CELL` characters: a row's long command list goes below its page's table, and a
row's earlier figures (`earlier`) with it.

Each row says where its figure came from, with exactly one mark: `"recorded": true` on a row a
script wrote with `--record` (its machine cell as `results_file.machine()` writes it, its command a
`python benchmarks/` line), `"historical": true` on a figure copied by hand from its page's section
(the machine as its author described it), which the table shows as "(historical)".
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "benchmarks" / "results.json"
PAGES = ROOT / "docs" / "benchmarks"
COLUMNS = ("target", "measured", "date", "machine", "command", "met")
BLOCK = re.compile(
    r"(<!-- results-table: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /results-table -->)", re.S
)
SUMMARY = re.compile(
    r"(<!-- results-summary: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /results-summary -->)", re.S
)
#: Where each summary is rendered (paths from the repository root).
SUMMARY_FILES = {"readme": ("README.md", "docs/index.md"), "algorithms": ("docs/algorithms.md",)}
#: The most characters a table cell may hold; longer text goes below the table.
MAX_CELL = 300
#: A row's mark of where its figure came from; each row carries exactly one, set to true.
MARKS = ("recorded", "historical")
#: What a script's ``--record-load`` may say about the machine (the machine cell's last part).
LOADS = ("alone", "shared")
#: The machine cell of a recorded row, as results_file.machine() writes it: CPU model, cores[, load].
RECORDED_MACHINE = re.compile(rf"[^,\s][^|]*, [1-9][0-9]* cores(, ({'|'.join(LOADS)}))?")
#: How every command of a recorded row starts (results_file.script_command()).
RECORDED_COMMAND = "python benchmarks/"
#: The line under a table with historical rows.
HISTORICAL_LEGEND = (
    "**(historical)**: a figure copied by hand from the section the target links to, with the command"
    " given there and the machine as its author described it; a row without the mark was written by"
    " its benchmark script's `--record` ([how](index.md#recording-a-row))."
)


def load(path: Path = RESULTS) -> dict[str, list[dict]]:
    return json.loads(path.read_text())["pages"]


def load_summaries(path: Path = RESULTS) -> dict[str, list[dict]]:
    return {k: v for k, v in json.loads(path.read_text()).get("summaries", {}).items() if k != "_about"}


def _cell(text: str, limit: int | None = None) -> str:
    if "|" in text or "\n" in text:
        raise ValueError(f"a table cell cannot hold '|' or a line break: {text!r}")
    if limit is not None and len(text) > limit:
        raise ValueError(f"a table cell holds {len(text)} characters, more than {limit}: {text[:80]!r}...")
    return text


def _command(row: dict) -> str:
    commands = row.get("command") or []
    if not commands:
        return "command not recorded"
    text = "; then ".join(f"`{c}`" for c in commands)
    if row.get("command_note"):
        text += f" ({row['command_note']})"
    return text


def origin(row: dict) -> str:
    """Where the row's figure came from: "recorded" (a script's ``--record`` wrote it) or
    "historical" (copied by hand). A ``ValueError`` for a row with no mark, both, a mark not set to
    true, or a recorded mark on a machine or command that ``--record`` would not have written."""
    marks = [m for m in MARKS if m in row]
    name = row.get("id", row.get("target"))
    if len(marks) != 1 or row[marks[0]] is not True:
        raise ValueError(f"row {name!r}: needs exactly one of {MARKS} set to true, has {marks}")
    if marks[0] == "recorded":
        if not RECORDED_MACHINE.fullmatch(row["machine"]):
            raise ValueError(
                f"row {name!r} is marked recorded, but its machine {row['machine']!r} is not "
                "'CPU model, N cores[, alone|shared]' as --record writes it"
            )
        commands = row.get("command") or []
        if not commands or not all(c.startswith(RECORDED_COMMAND) for c in commands):
            raise ValueError(
                f"row {name!r} is marked recorded, but its command {commands!r} is not "
                f"'{RECORDED_COMMAND}...' as --record writes it"
            )
    return marks[0]


def render(rows: list[dict]) -> str:
    """The Markdown table of one page: one line per row, the target linked to the page's section.
    A command list longer than a cell may hold, and a row's earlier figures, follow the table."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    below = []
    historical = False
    for row in rows:
        for key in ("target", "measured", "date", "machine", "met"):
            _cell(row[key], MAX_CELL)
        machine = row["machine"]
        if origin(row) == "historical":
            machine = _cell(f"{machine} (historical)", MAX_CELL)
            historical = True
        target = f"[{row['target']}]({row['section']})" if row.get("section") else row["target"]
        command = _command(row)
        if len(command) > MAX_CELL:
            n = len(row["command"])
            command = f"{n} commands, below the table ({row['id']})"
            below.append(f"- **{row['id']}**, the commands: {_command(row)}")
        if row.get("earlier"):
            below.append(f"- **{row['id']}**, the figures before and beside it: {_cell(row['earlier'])}")
        cells = (target, row["measured"], row["date"], machine, command, row["met"])
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    text = "\n".join(lines) + "\n"
    if historical:
        text += f"\n{HISTORICAL_LEGEND}\n"
    if below:
        text += "\nThe rows' long text:\n\n" + "\n".join(below) + "\n"
    return text


def _link(section: str, page: str, into: Path) -> str:
    """A row's section (relative to docs/benchmarks/) as a link from the file ``into``."""
    path, _, anchor = section.partition("#")
    dest = os.path.normpath(PAGES / (path or f"{page}.md"))
    rel = os.path.relpath(dest, into.parent)
    return f"{rel}#{anchor}" if anchor else rel


def render_summary(items: list[dict], pages: dict[str, list[dict]], into: Path) -> str:
    """A summary's table for the file ``into``: each item's label, then its row's figure (linked to
    the row's section), date and whether the target is met."""
    lines = ["| | figure | date | target |", "|---|---|---|---|"]
    for item in items:
        page, _, row_id = item["row"].partition("/")
        row = next((r for r in pages.get(page, []) if r.get("id") == row_id), None)
        if row is None:
            raise ValueError(f"summary item {item['label']!r}: no row {item['row']!r} in {RESULTS.name}")
        figure = _cell(row["measured"], MAX_CELL)
        if row.get("section"):
            figure = f"[{figure}]({_link(row['section'], page, into)})"
        lines.append(f"| {_cell(item['label'])} | {figure} | {row['date']} | {_cell(row['met'])} |")
    return "\n".join(lines) + "\n"


def compare_summaries(pages: dict[str, list[dict]], summaries: dict[str, list[dict]]) -> list[str]:
    """What differs between the summaries in the file and their copies: one line per problem."""
    problems = []
    for name, files in SUMMARY_FILES.items():
        for rel in files:
            path = ROOT / rel
            blocks = {m["name"]: m["body"] for m in SUMMARY.finditer(path.read_text())}
            if name not in summaries:
                problems.append(f"{RESULTS.name}: no summary '{name}'")
            elif name not in blocks:
                problems.append(f"{rel}: no '<!-- results-summary: {name} -->' block")
            elif blocks[name] != render_summary(summaries[name], pages, path):
                problems.append(f"{rel}: the '{name}' figures differ from {RESULTS.relative_to(ROOT)}")
    return problems


def write_summaries(pages: dict[str, list[dict]], summaries: dict[str, list[dict]]) -> None:
    for name, files in SUMMARY_FILES.items():
        for rel in files:
            path = ROOT / rel
            text = path.read_text()
            table = render_summary(summaries[name], pages, path)

            def fill(m: re.Match, name: str = name, table: str = table) -> str:
                return m[1] + table + m[4] if m["name"] == name else m[0]

            new = SUMMARY.sub(fill, text)
            if new != text:
                path.write_text(new)
                print(f"wrote {rel}")


def page_path(name: str, folder: Path = PAGES) -> Path:
    return folder / f"{name}.md"


def compare(pages: dict[str, list[dict]]) -> list[str]:
    """What differs between the file and the pages: one line per problem, empty when they agree."""
    problems = []
    for name, rows in pages.items():
        path = page_path(name)
        if not path.exists():
            problems.append(f"{name}: no page {path.relative_to(ROOT)}")
            continue
        blocks = {m["name"]: m["body"] for m in BLOCK.finditer(path.read_text())}
        try:
            table = render(rows)
        except ValueError as exc:  # a row without its mark, or a cell that would break the table
            problems.append(f"{RESULTS.relative_to(ROOT)}, page {name}: {exc}")
            continue
        if name not in blocks:
            problems.append(f"{path.relative_to(ROOT)}: no '<!-- results-table: {name} -->' block")
        elif blocks[name] != table:
            problems.append(f"{path.relative_to(ROOT)}: the table differs from {RESULTS.relative_to(ROOT)}")
    for path in sorted(PAGES.glob("*.md")):
        for m in BLOCK.finditer(path.read_text()):
            if m["name"] not in pages:
                problems.append(f"{path.relative_to(ROOT)}: block '{m['name']}' is not in the file")
    return problems


def write(pages: dict[str, list[dict]], folder: Path = PAGES) -> None:
    """Rewrite each page's table from its rows (the other text of the page is left as it is).
    Every table is rendered first: a row that cannot be (``ValueError``) leaves every page as it was."""
    tables = {name: render(rows) for name, rows in pages.items()}
    for name, table in tables.items():
        path = page_path(name, folder)
        text = path.read_text()

        def fill(m: re.Match, name: str = name, table: str = table) -> str:
            return m[1] + table + m[4] if m["name"] == name else m[0]

        new = BLOCK.sub(fill, text)
        if new != text:
            path.write_text(new)
            print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="rewrite the pages' tables from the file")
    mode.add_argument("--check", action="store_true", help="exit 1 if a page's table differs from the file")
    mode.add_argument("--ids", action="store_true", help="list PAGE/ID of every row (a script's --record)")
    args = parser.parse_args(argv)
    pages = load()
    if args.ids:
        for name, rows in pages.items():
            for row in rows:
                print(f"{name}/{row.get('id', '?')}: {row['target']}")
        return 0
    if args.write:
        try:
            write(pages)
        except ValueError as exc:  # a row without its mark, or a cell that would break the table
            print(f"{RESULTS.relative_to(ROOT)}: {exc}; no page written", file=sys.stderr)
            return 1
        write_summaries(pages, load_summaries())
        return 0
    if args.check:
        problems = compare(pages) + compare_summaries(pages, load_summaries())
        for p in problems:
            print(p, file=sys.stderr)
        return 1 if problems else 0
    for name, rows in pages.items():
        print(f"## {name}\n\n{render(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
