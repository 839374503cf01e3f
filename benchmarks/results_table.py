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
"""

from __future__ import annotations

import argparse
import json
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


def load(path: Path = RESULTS) -> dict[str, list[dict]]:
    return json.loads(path.read_text())["pages"]


def _cell(text: str) -> str:
    if "|" in text or "\n" in text:
        raise ValueError(f"a table cell cannot hold '|' or a line break: {text!r}")
    return text


def _command(row: dict) -> str:
    commands = row.get("command") or []
    if not commands:
        return "command not recorded"
    text = "; then ".join(f"`{c}`" for c in commands)
    if row.get("command_note"):
        text += f" ({row['command_note']})"
    return text


def render(rows: list[dict]) -> str:
    """The Markdown table of one page: one line per row, the target linked to the page's section."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        target = f"[{row['target']}]({row['section']})" if row.get("section") else row["target"]
        cells = (target, row["measured"], row["date"], row["machine"], _command(row), row["met"])
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines) + "\n"


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
        if name not in blocks:
            problems.append(f"{path.relative_to(ROOT)}: no '<!-- results-table: {name} -->' block")
        elif blocks[name] != render(rows):
            problems.append(f"{path.relative_to(ROOT)}: the table differs from {RESULTS.relative_to(ROOT)}")
    for path in sorted(PAGES.glob("*.md")):
        for m in BLOCK.finditer(path.read_text()):
            if m["name"] not in pages:
                problems.append(f"{path.relative_to(ROOT)}: block '{m['name']}' is not in the file")
    return problems


def write(pages: dict[str, list[dict]], folder: Path = PAGES) -> None:
    """Rewrite each page's table from its rows (the other text of the page is left as it is)."""
    for name, rows in pages.items():
        path = page_path(name, folder)
        text = path.read_text()
        table = render(rows)

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
        write(pages)
        return 0
    if args.check:
        problems = compare(pages)
        for p in problems:
            print(p, file=sys.stderr)
        return 1 if problems else 0
    for name, rows in pages.items():
        print(f"## {name}\n\n{render(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
