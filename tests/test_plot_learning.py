"""benchmarks/plot_learning.py: the band it draws is the seeds' mean, lowest and highest at points
every seed has reached, so a seed cut early by its budget does not pull the mean down."""

import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def plot():
    return runpy.run_path(str(ROOT / "benchmarks" / "plot_learning.py"))


def test_band_over_frames_and_minutes(plot, tmp_path):
    csv_path = tmp_path / "two.csv"
    csv_path.write_text(
        "tag,seed,minutes,frames,eval_success_rate\n"
        "a,0,0.5,20480,0.0\na,0,1.0,40960,0.5\na,0,1.5,61440,1.0\n"
        "a,1,0.6,20480,0.2\na,1,1.2,40960,0.7\n"  # seed 1 stopped at 40,960 frames
    )
    seeds = plot["read_curves"]([csv_path])["a"]
    frames, mean, low, high = plot["band"](seeds, 1)
    assert frames == [20480, 40960]  # 61,440: only seed 0 got there
    assert mean == pytest.approx([0.1, 0.6]) and low == [0.0, 0.5] and high == [0.2, 0.7]
    minutes, mean, low, high = plot["band"](seeds, 0)
    # From 0.6 (both evaluated once) to 1.2 (seed 1's last); each seed's latest value at that time.
    assert minutes == [0.6, 1.0, 1.2]
    assert mean == pytest.approx([0.1, 0.35, 0.6])


def test_writes_the_figure(plot, tmp_path, monkeypatch):
    csv_path = tmp_path / "one.csv"
    csv_path.write_text("tag,seed,minutes,frames,eval_success_rate\nb,0,0.5,20480,0.25\nb,0,1.0,40960,0.5\n")
    out = tmp_path / "fig" / "curves.png"
    monkeypatch.setattr("sys.argv", ["plot_learning.py", str(csv_path), "--out", str(out)])
    plot["main"]()
    assert out.stat().st_size > 0
