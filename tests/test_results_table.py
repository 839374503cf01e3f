"""The tables at the top of docs/benchmarks/ are rendered from docs/benchmarks/results.json
(benchmarks/results_table.py): a figure in those tables is one the file holds, with its command."""

import argparse
import datetime
import json
import os
import re
import runpy
import sys
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
        if path.name in ("index.md", "log.md"):  # the log holds the dated history, no targets
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
        table["render"]([dict(row, historical=True)])


def test_file_is_valid_json_with_pages():
    data = json.loads((ROOT / "docs" / "benchmarks" / "results.json").read_text())
    assert set(data["pages"]) >= {"learning", "throughput", "cameras"}


# --- a benchmark records its own row (benchmarks/results_file.py, the scripts' --record) ------------
@pytest.fixture(scope="module")
def results_file():
    return runpy.run_path(str(ROOT / "benchmarks" / "results_file.py"))


@pytest.fixture
def copies(tmp_path):
    """A copy of results.json and a page for ``throughput`` with text around its table: what
    ``record`` writes, without touching the real ones."""
    results = tmp_path / "results.json"
    results.write_text((ROOT / "docs" / "benchmarks" / "results.json").read_text())
    page = tmp_path / "throughput.md"
    page.write_text(
        "# T\n\nbefore\n\n<!-- results-table: throughput -->\nold table\n<!-- /results-table -->\n\nafter\n"
    )
    return results, page


def bench(name: str) -> dict:
    return runpy.run_path(str(ROOT / "benchmarks" / f"{name}.py"))


def test_every_row_has_a_unique_id(table):
    for name, rows in table["load"]().items():
        ids = [row.get("id") for row in rows]
        assert all(isinstance(i, str) and re.fullmatch(r"[a-z0-9][a-z0-9.-]*", i) for i in ids), (name, ids)
        assert len(set(ids)) == len(ids), f"{name}: ids repeat: {ids}"


def test_record_writes_the_row_and_the_page(results_file, copies, monkeypatch):
    results, page = copies
    before = json.loads(results.read_text())["pages"]
    monkeypatch.setattr(sys, "argv", ["/x/benchmarks/bench_collect.py", "--seconds", "5", "experiment=a b"])
    row = results_file["record"](
        "throughput",
        "collector",
        "0.80 (800 against 1,000 raw frames/s)",
        "missed",
        load="alone",
        results=results,
        folder=page.parent,
        today=datetime.date(2030, 1, 2),
    )
    after = json.loads(results.read_text())["pages"]
    written = next(r for r in after["throughput"] if r["id"] == "collector")
    assert written == row
    assert written["command"] == ["python benchmarks/bench_collect.py --seconds 5 'experiment=a b'"]
    assert "command_note" not in written  # the command is now recorded with its arguments
    assert (written["date"], written["met"]) == ("2030-01-02", "missed")
    assert written["machine"].endswith(f"{os.cpu_count()} cores, alone")
    assert "historical" in collector_before_row(before) and "recorded" not in collector_before_row(before)
    assert written["recorded"] is True and "historical" not in written  # the mark changes with the row
    collector_before = next(r for r in before["throughput"] if r["id"] == "collector")
    kept = ("target", "section")
    assert [written[k] for k in kept] == [collector_before[k] for k in kept]
    for name in before:  # every other row as it was
        assert len(after[name]) == len(before[name])
        for old, new in zip(before[name], after[name]):
            if (name, old["id"]) != ("throughput", "collector"):
                assert new == old
    text = page.read_text()
    assert text.startswith("# T\n\nbefore\n\n<!-- results-table: throughput -->\n| target |")
    assert text.endswith("<!-- /results-table -->\n\nafter\n") and "old table" not in text
    assert "| 0.80 (800 against 1,000 raw frames/s) | 2030-01-02 |" in text
    assert "`python benchmarks/bench_collect.py --seconds 5 'experiment=a b'`" in text
    collector_line = next(line for line in text.splitlines() if "| 0.80 (800 against" in line)
    assert f"| {written['machine']} |" in collector_line and "(historical)" not in collector_line
    historical = [r["measured"] for r in after["throughput"] if r.get("historical")]
    others = [line for line in text.splitlines() if line.startswith("| [") and line != collector_line]
    copied = [line for line in others if any(f"| {m} |" in line or f"{m}](" in line for m in historical)]
    assert copied and all(" (historical) | " in line for line in copied)  # still copied by hand
    assert "**(historical)**:" in text  # the legend, while the page has historical rows


def collector_before_row(pages: dict) -> dict:
    return next(r for r in pages["throughput"] if r["id"] == "collector")


def test_record_refuses_unknown_rows_and_broken_cells(results_file, copies):
    results, page = copies
    original = results.read_text()
    kw = {"results": results, "folder": page.parent}
    with pytest.raises(ValueError, match=r"no page 'nope'.*pages: learning, throughput"):
        results_file["record"]("nope", "x", "1", "met", **kw)
    with pytest.raises(ValueError, match=r"no row 'nope' on page 'peer'.*its rows: ppo-fps, fast-first-090"):
        results_file["record"]("peer", "nope", "1", "met", **kw)
    with pytest.raises(ValueError, match="cannot hold"):
        results_file["record"]("throughput", "collector", "0.8 | 0.9", "met", ["c"], **kw)
    assert results.read_text() == original  # nothing written on a refusal
    assert "old table" in page.read_text()


def test_row_spec_checks_the_row_before_a_run(results_file):
    assert results_file["row_spec"]("learning/ppo-5min") == ("learning", "ppo-5min")
    for bad, says in (
        ("learning", "expected PAGE/ID"),
        ("learning/", "expected PAGE/ID"),
        ("learning/nope", "its rows: ppo-5min"),
    ):
        with pytest.raises(argparse.ArgumentTypeError, match=says):
            results_file["row_spec"](bad)


def test_a_script_refuses_an_unknown_row_at_start(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["bench_learning.py", "--record", "learning/nope"])
    with pytest.raises(SystemExit) as exit_:
        bench("bench_learning")["parse_args"]()
    assert exit_.value.code == 2
    assert "no row 'nope' on page 'learning'" in capsys.readouterr().err


def test_machine_from_cpuinfo(results_file, tmp_path):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(
        "processor\t: 0\nmodel name\t: Intel(R) Xeon(R)  Gold 6230 CPU @ 2.10GHz\n"
        "processor\t: 1\nmodel name\t: Intel(R) Xeon(R)  Gold 6230 CPU @ 2.10GHz\n"
    )
    model = "Intel Xeon Gold 6230 CPU @ 2.10GHz"
    assert results_file["machine"]("shared", cpuinfo, 2) == f"{model}, 2 cores, shared"
    assert results_file["machine"](None, cpuinfo, 4) == f"{model}, 4 cores"
    assert results_file["machine"](None, tmp_path / "missing", 2) == "unknown CPU, 2 cores"


def test_met_of(results_file):
    met_of = results_file["met_of"]
    assert [met_of([True]), met_of([False])] == ["met", "missed"]
    assert met_of([True] * 3) == "met, 3 of 3"
    assert met_of([True, False, True]) == "met on 2 of 3"
    assert met_of([False] * 3) == "missed, 3 of 3"


def test_bench_learning_composes_its_row():
    b = bench("bench_learning")
    f32_09 = 0.8999999761581421  # 0.9 as TensorBoard's float32 gives it back
    curves = {
        1: [(1.0, 40960, 0.5), (5.1, 249856, 0.85)],
        0: [(1.0, 40960, 0.5), (2.24, 102400, f32_09), (5.0, 270336, 0.97)],
    }
    held_out = [(0, "random_urdfs_test", {"rate": 0.945}), (1, "random_urdfs_test", {"rate": 0.8})]
    text = b["record_text"](curves, held_out, 0.9)
    assert text == (
        "first >= 0.9 at 102k / - frames (2.2 / - min); final 0.97 / 0.85; "
        "random_urdfs_test 0.945 / 0.800 (seeds 0 / 1)"
    )
    assert b["record_text"](curves, [], 0.5).startswith("first >= 0.5 at 41k / 41k frames (1.0 / 1.0 min)")
    met = b["record_met"]
    assert met(curves, held_out, 0.9, None) == "see page"
    assert met(curves, held_out, 0.9, 0.9) == "met on 1 of 2"
    assert met(curves, held_out, 0.9, 0.8, "random_urdfs_test") == "met, 2 of 2"
    assert met(curves, held_out, 0.9, None, target_frames=80000) == "missed, 2 of 2"
    assert met(curves, held_out, 0.9, 0.9, target_frames=102400) == "met on 1 of 2"


def test_a_tag_run_on_another_seed_keeps_the_earlier_seeds_curves(tmp_path):
    write = bench("bench_learning")["write_curves"]
    csv_path = tmp_path / "tag.csv"
    write(csv_path, [("tag", 2, 1.5, 2048, 0.25), ("tag", 2, 3.0, 4096, 0.5)], [2])
    rows = write(csv_path, [("tag", 0, 1.4, 2048, 0.0)], [0])
    assert rows == [("tag", 2, 1.5, 2048, 0.25), ("tag", 2, 3.0, 4096, 0.5), ("tag", 0, 1.4, 2048, 0.0)]
    rows = write(csv_path, [("tag", 2, 1.6, 2048, 0.75)], [2])  # a seed run again replaces its own
    assert rows == [("tag", 0, 1.4, 2048, 0.0), ("tag", 2, 1.6, 2048, 0.75)]
    assert csv_path.read_text().count("\n") == 3  # the header and both rows


def test_bench_peer_composes_its_row():
    b = bench("bench_peer")
    ours = b["summary"](
        [(2.0, 81920, 0.5, 32), (3.0, 122880, 0.9, 32), (5.0, 270336, 0.92, 100)],
        [(1.0, 40960, 900.0), (5.0, 270000, 1000.0)],
    )
    sb3 = b["summary"](
        [(4.0, 81920, 0.91, 32), (5.0, 180000, 0.90, 100)], [(1.0, 20480, 700.0), (5.0, 180000, 800.0)]
    )
    text = b["record_text"](ours, sb3, 0)
    assert text == (
        "1.25x SPS, 1.50x frames/s from launch; first >= 0.9 in 0.75 of SB3's time; "
        "final 0.92 against SB3's 0.90 (seed 0)"
    )
    met = b["record_met"]
    assert met(ours, sb3, "launch-fps", None) == "see page"
    assert met(ours, sb3, "launch-fps", 2.5) == "missed"
    assert met(ours, sb3, "launch-fps", 1.5) == "met"
    assert met(ours, sb3, "first-0.9", 0.5) == "missed"  # 0.75 of SB3's time, not at most half
    assert met(ours, sb3, "first-0.9", 0.8) == "met"
    assert met(ours, sb3, "final", 1.0) == "met"
    never = b["summary"]([(5.0, 270336, 0.8, 100)], [(5.0, 270000, 1000.0)])
    assert "first >= 0.9 at - against SB3's 4.0 min" in b["record_text"](never, sb3, 1)
    assert met(never, sb3, "first-0.9", 0.5) == "missed"


def test_bench_core_expert_env_scale_soak_compose_their_rows():
    assert bench("bench_core")["record_text"]({"shipped": 1363.0}, 2154.0, 2) == (
        "0.63 (1,363 against 2,154 raw frames/s, medians of 2 rounds)"
    )
    assert bench("bench_core")["record_text"]({"a": 1000.0, "b": 1500.0}, 2000.0, 3) == (
        "a 0.50, b 0.75 of raw (2,000 frames/s, medians of 3 rounds)"
    )
    cases = [
        ("panda", "cube", "none", 100, 100),
        ("panda", "cube", "default", 98, 100),
        ("xarm6", "primitives", "none", 90, 100),
    ]
    assert bench("bench_expert")["record_text"](cases) == (
        "panda cube: none 100/100, default 98/100; xarm6 primitives: none 90/100"
    )
    assert bench("bench_env")["record_text"]({"ee_delta": 0.641, "joint_delta": 0.72}) == (
        "0.64 / 0.72 (`ee_delta` / `joint_delta`)"
    )
    assert bench("bench_scale")["record_text"]({"process": 1000.0, "ray": 940.0, "ray_2nodes": 890.0}) == (
        "ray 0.94, ray_2nodes 0.89 of process's frames/s"
    )
    rows = [
        (1, "20.0", 4096, 4096, 0, "ok"),
        (2, "30.0", 9216, 8192, 1024, "ok"),
        (3, "25.0", 12288, 8192, 4096, "lost 4096 frames"),
    ]
    assert bench("soak_resume")["soak_text"](rows) == "2 of 3 cycles ok, at most 4,096 frames lost per kill"


# --- one source: the README's, docs/index.md's and the guides' figures are rows of results.json -----
def test_summaries_match_the_file(table):
    """README.md, docs/index.md and docs/algorithms.md quote figures rendered from results.json's
    rows (``summaries``): a figure typed into one copy, or a row changed without `--write`, fails."""
    pages, summaries = table["load"](), table["load_summaries"]()
    assert set(summaries) == set(table["SUMMARY_FILES"])
    assert table["compare_summaries"](pages, summaries) == []


def test_a_changed_summary_figure_is_caught(table):
    pages, summaries = table["load"](), table["load_summaries"]()
    pages["learning"] = [dict(r, measured="0.99 / 0.99 / 0.99") for r in pages["learning"]]
    problems = table["compare_summaries"](pages, summaries)
    assert any("README.md" in p and "differ" in p for p in problems)
    assert any("docs/index.md" in p and "differ" in p for p in problems)


def test_a_summary_names_only_rows_that_exist(table):
    with pytest.raises(ValueError, match="no row 'learning/nope'"):
        table["render_summary"]([{"label": "x", "row": "learning/nope"}], table["load"](), ROOT / "README.md")


def test_no_cell_over_the_limit(table):
    """No cell of a results table or a summary holds more than MAX_CELL characters (a linked figure:
    its text): long command lists and earlier figures are rendered below the table."""
    limit = table["MAX_CELL"]
    pages, summaries = table["load"](), table["load_summaries"]()
    rendered = [table["render"](rows) for rows in pages.values()]
    rendered += [table["render_summary"](items, pages, ROOT / "README.md") for items in summaries.values()]
    for text in rendered:
        for line in text.splitlines():
            if line.startswith("|"):
                for cell in line.strip("| ").split(" | "):
                    shown = re.sub(r"\]\([^)\s]+\)$", "", cell).lstrip("[")
                    assert len(shown) <= limit, f"a cell of {len(shown)} characters: {shown[:80]}..."
    row = {"target": "t", "measured": "x" * (limit + 1), "date": "2026-01-01", "machine": "m", "met": "met"}
    row["historical"] = True
    with pytest.raises(ValueError, match="more than"):
        table["render"]([row])
    long = dict(row, measured="1", id="r", command=["python a.py " + "x" * limit])
    rendered = table["render"]([long])
    assert "1 commands, below the table (r)" in rendered and "- **r**, the commands:" in rendered


# --- where a row's figure came from: written by --record, or copied by hand ("historical") ---------
#: The machine cell results_file.machine() writes, spelled out here apart from results_table's own.
MACHINE_FORM = re.compile(r"[^,]+, [1-9][0-9]* cores(, (alone|shared))?")


def test_every_row_is_recorded_or_historical(table):
    """Each row carries exactly one mark, set to true, and its page's table shows which."""
    for name, rows in table["load"]().items():
        rendered = table["render"](rows)
        for row in rows:
            marks = [m for m in ("recorded", "historical") if m in row]
            assert len(marks) == 1 and row[marks[0]] is True, f"{name}/{row['id']}: marks {marks}"
            assert table["origin"](row) == marks[0]
            shown = f"| {row['machine']} (historical) |" in rendered
            assert shown == (marks[0] == "historical"), f"{name}/{row['id']}"
        has_historical = any(row.get("historical") for row in rows)
        assert ("**(historical)**:" in rendered) == has_historical, name


def test_a_recorded_row_is_one_record_could_have_written(table):
    """A row marked recorded has the machine cell machine() writes and a benchmark script's command."""
    for name, rows in table["load"]().items():
        for row in rows:
            if row.get("recorded"):
                assert MACHINE_FORM.fullmatch(row["machine"]), f"{name}/{row['id']}: {row['machine']!r}"
                assert all(c.startswith("python benchmarks/") for c in row["command"]), row["command"]


def test_origin_refuses_a_row_without_one_true_mark(table, results_file, tmp_path):
    origin = table["origin"]
    row = {
        "id": "r",
        "target": "t",
        "measured": "1",
        "date": "2026-01-01",
        "machine": results_file["machine"]("alone", tmp_path / "missing", 2),
        "command": ["python benchmarks/bench_env.py --steps 10"],
        "met": "met",
    }
    assert MACHINE_FORM.fullmatch(row["machine"]) and table["RECORDED_MACHINE"].fullmatch(row["machine"])
    assert origin(dict(row, recorded=True)) == "recorded"
    assert origin(dict(row, historical=True)) == "historical"
    for bad in (
        row,
        dict(row, recorded=True, historical=True),
        dict(row, historical="yes"),
        dict(row, recorded=False),
    ):
        with pytest.raises(ValueError, match="exactly one of"):
            origin(bad)
        with pytest.raises(ValueError, match="exactly one of"):
            table["render"]([bad])


def test_a_hand_typed_row_cannot_pass_for_recorded(table, results_file, tmp_path):
    """The machine cells typed by hand ("reference, alone") and commands that are not a benchmark
    script's are refused under a recorded mark; what machine() writes is accepted with any load."""
    origin = table["origin"]
    for pages in table["load"]().values():
        for row in pages:  # every hand-typed row in the file would be refused if marked recorded
            if row.get("historical") and not MACHINE_FORM.fullmatch(row["machine"]):
                recorded = {k: v for k, v in row.items() if k != "historical"} | {"recorded": True}
                with pytest.raises(ValueError, match="is not 'CPU model"):
                    origin(recorded)
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("model name\t: Intel(R) Core(TM) i7-8550U CPU @ 1.80GHz\n")
    base = {"id": "r", "machine": "", "command": ["python benchmarks/bench_env.py"], "recorded": True}
    for load in (None, "alone", "shared"):
        assert origin(dict(base, machine=results_file["machine"](load, cpuinfo, 8))) == "recorded"
    good = dict(base, machine=results_file["machine"]("alone", cpuinfo, 8))
    for commands in (
        [],
        ["python scripts/train.py seed=0"],
        ["python benchmarks/a.py", "scontrol requeue 1"],
    ):
        with pytest.raises(ValueError, match="its command"):
            origin(dict(good, command=commands))
    with pytest.raises(ValueError, match="load 'nice 19'"):
        results_file["record"](
            "throughput", "collector", "1", "met", load="nice 19", results=tmp_path / "absent.json"
        )


def test_an_unmarked_row_fails_check_and_write(table, tmp_path):
    pages = table["load"]()
    pages["peer"] = [{k: v for k, v in r.items() if k != "historical"} for r in pages["peer"]]
    problems = table["compare"](pages)
    assert any("page peer" in p and "exactly one of" in p for p in problems), problems
    for name in pages:  # --write renders every page before it writes one: none is touched
        (tmp_path / f"{name}.md").write_text(
            f"<!-- results-table: {name} -->\nold\n<!-- /results-table -->\n"
        )
    with pytest.raises(ValueError, match="exactly one of"):
        table["write"](pages, tmp_path)
    assert all("\nold\n" in (tmp_path / f"{name}.md").read_text() for name in pages)
