"""benchmarks/bench_grasp_depth.py: the depth and offset docs/history/robots.md compares are read at the
first grasped step, the hold is counted to its end, and episodes are grouped by the evaluation's
outcome."""

import runpy
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_expert_grasps_are_read_below_the_centre_and_grouped_by_outcome(capsys) -> None:
    bench = runpy.run_path(str(ROOT / "benchmarks" / "bench_grasp_depth.py"))
    by_outcome = bench["main"](["policy=scripted", "episodes=3", "seed=5"])
    assert sum(len(d) for d in by_outcome.values()) == 3
    held = by_outcome["success"]  # the expert lifts the cube on these seeds (bench_expert: 98/100)
    # The grasp point closes between the cube's centre and a few cm below it (the cube is 5 cm),
    # within a centimetre of the centre horizontally, and the fingers keep it to the episode's end.
    assert held and all(g is not None and 0.0 < g.depth < 0.025 and g.offset < 0.01 for g in held)
    assert all(10 < g.steps_held < 50 and g.let_go is None for g in held)  # still held at the end
    assert "success" in capsys.readouterr().out
