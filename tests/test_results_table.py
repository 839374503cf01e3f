"""The tables at the top of docs/benchmarks/ are rendered from docs/benchmarks/results.json
(benchmarks/results_table.py): a figure in those tables is one the file holds, with its command."""

import json
import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def table():
    return runpy.run_path(str(ROOT / "benchmarks" / "results_table.py"))


def test_pages_match_the_file(table):
    assert table["compare"](table["load"]()) == []


def test_every_benchmark_page_opens_with_its_table(table):
    pages = table["load"]()
    for path in sorted((ROOT / "docs" / "benchmarks").glob("*.md")):
        if path.name == "index.md":
            continue
        assert path.stem in pages, f"{path.name} has no rows in results.json"
        text = path.read_text()
        first_section = text.index("\n## ")
        assert text.index(f"<!-- results-table: {path.stem} -->") < text.index("\n## ", first_section + 1), (
            f"{path.name}: the table is not in the page's first section"
        )


def test_every_row_has_what_a_reader_needs(table):
    for name, rows in table["load"]().items():
        for row in rows:
            for key in ("target", "measured", "date", "machine", "met"):
                assert row.get(key), f"{name}: a row without {key}: {row}"
            assert row["date"][:2] == "20" and len(row["date"]) == 10, row
            rendered = table["render"]([row])
            assert row["measured"] in rendered
            assert ("command not recorded" in rendered) == (not row.get("command"))


def test_a_changed_figure_is_caught(table):
    pages = table["load"]()
    pages["learning"] = [dict(pages["learning"][0], measured="0.99 / 0.99 / 0.99")]
    problems = table["compare"](pages)
    assert any("learning.md" in p and "differs" in p for p in problems)


def test_cells_cannot_break_the_table(table):
    with pytest.raises(ValueError):
        row = {"target": "a | b", "measured": "1", "date": "2026-01-01", "machine": "m", "met": "met"}
        table["render"]([row])


def test_file_is_valid_json_with_pages():
    data = json.loads((ROOT / "docs" / "benchmarks" / "results.json").read_text())
    assert set(data["pages"]) >= {"learning", "throughput", "cameras"}
