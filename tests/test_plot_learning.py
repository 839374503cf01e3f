"""benchmarks/plot_learning.py: a CSV's curves reach ``rlgrasp-report``'s band as each seed's
(x, success) arrays, so a seed cut early by its budget ends the band instead of pulling it down."""

import runpy
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

CSV = (
    "tag,seed,minutes,frames,eval_success_rate\n"
    "a,0,0.5,20480,0.0\na,0,1.0,40960,0.5\na,0,1.5,61440,1.0\n"
    "a,1,0.6,20480,0.2\na,1,1.2,40960,0.7\n"  # seed 1 stopped at 40,960 frames
)


@pytest.fixture(scope="module")
def plot():
    return runpy.run_path(str(ROOT / "benchmarks" / "plot_learning.py"))


def test_curves_along_frames_and_minutes(plot, tmp_path):
    (tmp_path / "a.csv").write_text(CSV)
    seeds = plot["read_curves"]([tmp_path / "a.csv"])["a"]
    frames = plot["along"](seeds, 1)
    assert [list(x) for x, _ in frames] == [[20480, 40960, 61440], [20480, 40960]]
    assert [list(v) for _, v in frames] == [[0.0, 0.5, 1.0], [0.2, 0.7]]
    assert [list(x) for x, _ in plot["along"](seeds, 0)] == [[0.5, 1.0, 1.5], [0.6, 1.2]]
    b = plot["band"](frames)
    assert b["x"][0] == 20480 and b["x"][-1] == 40960  # every point averages both seeds
    assert b["mean"][-1] == pytest.approx(0.6) and np.all(b["low"] <= b["high"])


def test_reads_bench_peer_sides_and_writes_the_figure(plot, tmp_path, monkeypatch):
    peer = tmp_path / "peer_seed0.csv"
    peer.write_text(
        "side,seed,minutes,frames,eval_success_rate,episodes\n"
        "rlgrasp,0,0.5,20480,0.25,32\nrlgrasp,0,1.0,40960,0.5,32\nsb3,0,0.7,20480,0.0,32\n"
        "sb3,0,1.4,40960,0.25,32\n"
    )
    assert set(plot["read_curves"]([peer])) == {"rlgrasp", "sb3"}
    out = tmp_path / "fig" / "curves.png"
    monkeypatch.setattr("sys.argv", ["plot_learning.py", str(peer), "--out", str(out)])
    plot["main"]()
    assert out.stat().st_size > 0
