"""Where a run's wall clock goes (``rlgrasp.train.tracking.metrics.Phases``): train.log's last line."""

from __future__ import annotations

import time

from rlgrasp.train.tracking.metrics import Phases, parse_phases, process_age_s


def test_phases_take_inner_phases_out_of_outer_ones_and_read_back() -> None:
    phases = Phases()
    phases.mark("start-up")
    with phases("periodic evaluations"):
        time.sleep(0.05)
        with phases("checkpoints"):
            time.sleep(0.1)
    seconds = dict(phases.seconds)
    assert 0.04 < seconds["periodic evaluations"] < 0.09 and seconds["checkpoints"] >= 0.1
    line = phases.line()
    figures = parse_phases(line)
    assert line.startswith("time from launch") and set(figures) == {
        "total",
        "start-up",
        "periodic evaluations",
        "checkpoints",
        "other",
    }
    assert abs(figures["total"] - sum(v for k, v in figures.items() if k != "total")) < 0.3


def test_the_start_up_counts_from_the_launch_of_the_process() -> None:
    assert process_age_s() > 0.0  # the interpreter and the imports came before this test
    phases = Phases()
    phases.mark("start-up")
    assert phases.seconds["start-up"] >= process_age_s() - 1.0
