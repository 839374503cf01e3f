"""Automatic domain randomization: the update rule on synthetic outcomes (no simulator), the env's
boundary episodes, the ranges reaching the workers between batches, the preset file, and a short
real run through a checkpoint and a resume."""

from __future__ import annotations

import dataclasses
import runpy
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from rlgrasp.adr import NOT_BOUNDARY, AdrState, draw_boundary, parse_settings
from rlgrasp.envs.factory import env_factory
from rlgrasp.envs.randomization import PARAMS, Randomizer, Range
from rlgrasp.policy_file import load_checkpoint
from rlgrasp.train.collection.adr_sync import RANGES_FILE, AdrSync
from rlgrasp.train.collection.collectors import shut_down
from rlgrasp.train.evaluation.evaluate import periodic_evaluator
from rlgrasp.train.loop import train
from rlgrasp.train.parts import build_parts
from tests.helpers import record_differences, train_twice

ROOT = Path(__file__).resolve().parents[1]
ADR_SPEC = yaml.safe_load((ROOT / "configs/randomization/adr.yaml").read_text())["randomization"]


def _settings(**keys):
    params = {
        "object_mass": {"nominal": 0.1, "limits": [0.01, 0.45], "step": 0.1},
        "action_delay": {"nominal": 0, "limits": [0, 2], "step": 1, "integer": True},
        "joint_damping": {"nominal": 0.0, "limits": [0.0, 1.0], "step": 0.25},
    }
    return parse_settings(
        {"params": params, "buffer_size": 4, "low_threshold": 0.4, "high_threshold": 0.7, **keys}
    )


def _code(settings, name: str, bound: int) -> int:
    return 2 * settings.names.index(name) + bound


# --- the update rule -----------------------------------------------------------------------------
def test_the_shipped_preset_parses_with_every_non_task_parameter() -> None:
    randomizer = Randomizer(ADR_SPEC)
    assert randomizer.adr is not None and len(randomizer.adr.names) == 17
    for name in randomizer.adr.names:  # every range starts at the nominal value
        r = randomizer.ranges[name]
        assert r.low == r.high == PARAMS[name].nominal, name
    assert randomizer.ranges["object_yaw"].high > 0  # the task's own pose keeps its range


def test_the_periodic_evaluation_plays_eval_randomization_when_set(train_cfg) -> None:
    """An ADR run's evaluation env samples ADR's start ranges; with ``eval.randomization=default``
    it plays the preset the run aims at, and training's env factory is left as it was."""
    cfg = train_cfg("experiment=smoke", "randomization=adr")
    make_env = env_factory(cfg.env)
    aimed = train_cfg("experiment=smoke", "randomization=adr", "eval.randomization=default")
    for config, expected_mass in ((cfg, (0.1, 0.1)), (aimed, (0.05, 0.5))):
        env = periodic_evaluator(make_env, config).make_env()
        try:
            mass = env.randomizer.ranges["object_mass"]
            assert (mass.low, mass.high) == expected_mass
            assert (env.randomizer.adr is None) == (config is aimed)
        finally:
            env.close()
    assert make_env.keywords["randomization"]["adr"]  # training still draws ADR's ranges


def test_a_full_buffer_widens_above_the_high_threshold_and_narrows_below_the_low() -> None:
    s = _settings()
    state = AdrState(s)
    high = _code(s, "object_mass", 1)
    for _ in range(3):
        assert state.record(high, 1.0) is None  # not full yet: no move
    assert state.record(high, 1.0) is not None
    assert state.ranges["object_mass"] == pytest.approx([0.1, 0.2])
    assert state.buffers[high] == []  # cleared after a decision
    for outcome in (1, 1, 1, 0):  # 0.75 >= 0.7: widens again
        state.record(high, outcome)
    assert state.ranges["object_mass"] == pytest.approx([0.1, 0.3])
    for outcome in (1, 0, 1, 0):  # 0.5: between the thresholds, stays
        state.record(high, outcome)
    assert state.ranges["object_mass"] == pytest.approx([0.1, 0.3])
    for outcome in (1, 0, 0, 0):  # 0.25 <= 0.4: narrows
        state.record(high, outcome)
    assert state.ranges["object_mass"] == pytest.approx([0.1, 0.2])
    low = _code(s, "object_mass", 0)
    for _ in range(4):
        state.record(low, 1.0)
    assert state.ranges["object_mass"] == pytest.approx([0.01, 0.2])  # 0.1 - 0.1 stops at the limit


def test_bounds_never_pass_their_limits_nor_cross_the_nominal_value() -> None:
    s = _settings()
    state = AdrState(s)
    rng = np.random.default_rng(0)
    codes = range(2 * len(s.params))
    for _ in range(3000):  # a random stream, mostly successes early and failures late
        code = int(rng.choice(codes))
        state.record(code, float(rng.random() < 0.8 if state.moves < 20 else rng.random() < 0.2))
        for p in s.params:
            low, high = state.ranges[p.name]
            assert p.low_limit <= low <= p.nominal <= high <= p.high_limit, (p.name, low, high)
    assert state.moves > 20


def test_entropy_is_the_mean_log_width_and_rises_as_ranges_widen() -> None:
    s = _settings()
    state = AdrState(s, {"object_mass": (0.1, 0.2), "action_delay": (0, 1), "joint_damping": (0.0, 0.5)})
    assert state.entropy() == pytest.approx(np.mean(np.log([0.1, 1.0, 0.5])))
    before = state.entropy()
    for _ in range(4):
        state.record(_code(s, "joint_damping", 1), 1.0)
    assert state.entropy() > before


def test_boundary_episodes_come_with_probability_p_over_the_bounds_that_can_move() -> None:
    s = _settings()
    ranges = {"object_mass": (0.1, 0.1), "action_delay": (0, 0), "joint_damping": (0.0, 0.0)}
    rng = np.random.default_rng(1)
    draws = [draw_boundary(rng, s, ranges, 0.3) for _ in range(20000)]
    boundary = [d for d in draws if d != NOT_BOUNDARY]
    assert len(boundary) / len(draws) == pytest.approx(0.3, abs=0.015)
    # action_delay's and joint_damping's low bounds sit at nominal = hard limit: never drawn
    movable = {
        _code(s, "object_mass", 0),
        _code(s, "object_mass", 1),
        _code(s, "action_delay", 1),
        _code(s, "joint_damping", 1),
    }
    counts = {c: boundary.count(c) for c in set(boundary)}
    assert set(counts) == movable
    assert max(counts.values()) / min(counts.values()) < 1.15  # uniform over the movable bounds
    assert all(draw_boundary(rng, s, ranges, 0.0) == NOT_BOUNDARY for _ in range(1000))


def test_a_boundary_episode_pins_its_parameter_at_the_bound() -> None:
    randomizer = Randomizer({"preset": "none", "adr": {**ADR_SPEC["adr"]}})
    rng = np.random.default_rng(0)
    for _ in range(20):  # before the learner pushes anything: start ranges, no boundary episode
        assert randomizer.sample(rng)["object_mass"] == 0.1 and randomizer.info()["adr_boundary"] == -1
    randomizer.set_ranges({"object_mass": (0.05, 0.6), "action_delay": (0, 3)}, boundary_prob=1.0)
    seen = set()
    for _ in range(400):
        values = randomizer.sample(rng)
        param, bound = randomizer.adr.decode(randomizer.info()["adr_boundary"])
        if param.name in ("object_mass", "action_delay"):
            expected = {"object_mass": (0.05, 0.6), "action_delay": (0, 3)}[param.name][bound]
            assert values[param.name] == expected
            seen.add((param.name, bound))
        assert 0.05 <= values["object_mass"] <= 0.6
    # action_delay's low bound is its nominal value and its hard limit (0): never a boundary
    assert seen == {("object_mass", 0), ("object_mass", 1), ("action_delay", 1)}
    assert isinstance(randomizer.sample(rng)["action_delay"], int)


def test_the_state_round_trips_through_a_checkpoint_file(tmp_path: Path) -> None:
    s = _settings()
    state = AdrState(s)
    for outcome in (1, 1, 1, 1, 1, 0):
        state.record(_code(s, "object_mass", 1), outcome)
    state.record(_code(s, "joint_damping", 1), 1)
    torch.save({"adr": state.state_dict()}, tmp_path / "c.pt")
    again = AdrState(s)
    again.load_state_dict(torch.load(tmp_path / "c.pt", weights_only=True)["adr"])
    assert again.ranges == state.ranges and again.buffers == state.buffers and again.moves == state.moves


def test_the_ranges_file_loads_as_a_randomization(tmp_path: Path) -> None:
    sync = AdrSync(Randomizer(ADR_SPEC))
    sync.state.ranges["object_mass"] = [0.05, 0.7]
    sync.state.ranges["action_delay"] = [0, 2]
    path = sync.write_ranges(tmp_path)
    loaded = Randomizer(str(path))
    assert loaded.adr is None
    assert (loaded.ranges["object_mass"].low, loaded.ranges["object_mass"].high) == (0.05, 0.7)
    assert (loaded.ranges["action_delay"].low, loaded.ranges["action_delay"].high) == (0, 2)
    assert loaded.ranges["object_x"] == Randomizer("none").ranges["object_x"]
    values = loaded.sample(np.random.default_rng(0))
    assert 0.05 <= values["object_mass"] <= 0.7 and values["action_delay"] in (0, 1, 2)
    with pytest.raises(ValueError, match="randomization file .*nowhere.yaml"):
        Randomizer(str(tmp_path / "nowhere.yaml"))


def test_the_ranges_file_keeps_the_base_preset_and_log_uniform_draws(tmp_path: Path) -> None:
    """A curriculum over a preset (``randomization=adr_objects``): the file holds the preset's other
    ranges, and a log-uniform ADR parameter stays log-uniform in the env and in the file."""
    spec = yaml.safe_load((ROOT / "configs/randomization/adr_objects.yaml").read_text())["randomization"]
    randomizer = Randomizer(spec)
    assert randomizer.ranges["object_mass"].log and not randomizer.ranges["object_size_scale"].log
    assert randomizer.ranges["finger_friction"] == Randomizer("default").ranges["finger_friction"]
    randomizer.set_ranges({"object_mass": (0.05, 0.5)}, boundary_prob=0.0)
    assert randomizer.ranges["object_mass"] == Randomizer("default").ranges["object_mass"]

    sync = AdrSync(Randomizer(spec))
    sync.state.ranges["object_mass"] = [0.05, 0.3]
    loaded = Randomizer(sync.write_ranges(tmp_path).as_posix())
    assert loaded.ranges["object_mass"] == Range(0.05, 0.3, log=True)
    others = set(PARAMS) - {"object_mass", "object_size_scale"}
    default = Randomizer("default").ranges
    assert {k: loaded.ranges.get(k) for k in others} == {k: default.get(k) for k in others}
    with pytest.raises(ValueError, match="a log-uniform range needs limits above 0"):
        parse_settings(
            {"params": {"joint_damping": {"nominal": 0.0, "limits": [0.0, 1.0], "step": 0.1, "log": True}}}
        )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"params": {"object_mass": {"limits": [0.01, 1.0], "step": 0.1}}}, "needs ['nominal']"),
        ({"params": {"object_mass": {"nominal": 0.1, "step": 0.1}}}, "needs ['limits']"),
        (
            {"params": {"object_mass": {"nominal": 0.1, "limits": [0.2, 1.0], "step": 0.1}}},
            "exclude the nominal",
        ),
        ({"params": {"object_mass": {"nominal": 0.1, "limits": [0.01, 1.0], "step": 0}}}, "step must be > 0"),
        (
            {"params": {"object_mass": {"nominal": 0.1, "limits": [0.01, 1.0], "step": -1}}},
            "step must be > 0",
        ),
        ({"low_threshold": -0.1}, "low_threshold=-0.1: must be in [0, 1]"),
        ({"high_threshold": 1.5}, "high_threshold=1.5: must be in [0, 1]"),
        ({"low_threshold": 0.8, "high_threshold": 0.5}, "low_threshold=0.8: must be below high_threshold"),
        ({"buffer_size": 0}, "buffer_size=0: must be an integer >= 1"),
        ({"boundary_prob": 2}, "boundary_prob=2.0: must be in [0, 1]"),
    ],
)
def test_bad_settings_are_refused_naming_the_key(change, message) -> None:
    node = {**ADR_SPEC["adr"], **change}
    with pytest.raises(ValueError) as err:
        Randomizer({"preset": "none", "adr": node})
    assert message in str(err.value) and "\n" not in str(err.value)


# --- through the collectors and a real run ---------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("collector", ["single", "process"])
def test_the_ranges_reach_the_workers_envs_between_batches(collector: str, train_cfg) -> None:
    _check_the_ranges_reach_the_envs(train_cfg, f"collector={collector}")


@pytest.mark.slow
def test_the_ranges_reach_ray_workers_envs(request, train_cfg) -> None:
    cluster = request.getfixturevalue("ray_cluster")
    _check_the_ranges_reach_the_envs(
        train_cfg,
        "collector=ray",
        f"collector.ray.address={cluster.address}",
        "collector.ray.memory_per_worker_gb=0.25",
    )


def _check_the_ranges_reach_the_envs(train_cfg, *collector: str) -> None:
    cfg = train_cfg(
        "experiment=smoke",
        "randomization=adr",
        *collector,
        "collector.steps_per_env=120",
        "collector.num_workers=1",
    )
    parts = build_parts(cfg)
    sync = AdrSync.from_env_cfg(cfg.env)
    sync.settings = dataclasses.replace(sync.settings, boundary_prob=1.0)
    sync.state.ranges["object_mass"] = [0.05, 0.6]
    collector_ = parts.make_collector()
    try:
        batches = iter(collector_)
        first = next(batches)  # built from the config: no boundary episode yet
        assert (first["next", "adr_boundary"] == NOT_BOUNDARY).all()
        sync.push(collector_)  # between batches, as rlgrasp.train.collection.batches does
        # episodes already running keep their draw; those that start after the push are boundary ones
        second, third = next(batches), next(batches)
        done = third["next", "done"].squeeze(-1)
        assert done.any() and (third["next", "adr_boundary"][done] != NOT_BOUNDARY).all()
        assert (second["next", "adr_boundary"] != NOT_BOUNDARY).any()
        # each worker's envs, read back through the same channel
        workers = collector_.map_fn("env.base_env._env.get_attr", list_of_args=[("randomizer",)])
        randomizers = [r for worker in workers for r in worker]
        assert len(randomizers) == 2
        masses = {(r.ranges["object_mass"].low, r.ranges["object_mass"].high) for r in randomizers}
        assert masses == {(0.05, 0.6)}
    finally:
        shut_down(collector_)


def _scalars(run_dir: Path) -> EventAccumulator:
    acc = EventAccumulator(str(run_dir / "tensorboard"), size_guidance={"scalars": 0})
    acc.Reload()
    return acc


@pytest.mark.slow
def test_a_short_run_moves_bounds_logs_them_and_a_resume_continues(tmp_path: Path, train_cfg) -> None:
    """From the `default` ranges with one-episode buffers, the untrained policy's failures at the
    bounds narrow them: bounds move, the curves and the ranges file are written, and a resume starts
    from the checkpoint's ranges, not the config's."""
    run_dir = tmp_path / "run"
    adr = [
        "randomization=adr",
        "env.randomization.adr.start=default",
        "env.randomization.adr.buffer_size=1",
        "eval.episodes=2",
        "eval.final_episodes=2",
    ]
    train(train_cfg("experiment=smoke", *adr, run_dir=run_dir))
    ckpt = load_checkpoint(run_dir)
    state = ckpt["adr"]
    assert state["moves"] >= 1
    start = AdrSync.from_env_cfg(ckpt["config"]["env"]).state
    assert state["ranges"] != start.ranges
    tags = set(_scalars(run_dir).Tags()["scalars"])
    assert {"adr/entropy", "adr/object_mass/low", "adr/object_mass/high", "adr/gravity_z/high"} <= tags
    entropy = [e.value for e in _scalars(run_dir).Scalars("adr/entropy")]
    assert entropy[-1] < start.entropy()  # narrowing lowers it
    written = yaml.safe_load((run_dir / RANGES_FILE).read_text())
    assert [written[k]["low"] for k in state["ranges"]] == [v[0] for v in state["ranges"].values()]

    train(train_cfg("experiment=smoke", *adr, f"resume={run_dir}", "total_frames=4096", run_dir=run_dir))
    after = load_checkpoint(run_dir)["adr"]
    assert after["moves"] > state["moves"]  # the count goes on from the checkpoint's
    steps = [e.step for e in _scalars(run_dir).Scalars("adr/entropy")]
    assert steps == sorted(steps) and steps[-1] == 4096


@pytest.mark.slow
def test_a_seed_gives_one_adr_run_on_this_machine(tmp_path: Path, train_cfg) -> None:
    """Boundary draws, moves and ranges included: twice the same seed, the same curves bit for bit."""
    adr = (
        "randomization=adr",
        "env.randomization.adr.start=default",
        "env.randomization.adr.buffer_size=1",
        "collector.steps_per_env=128",
        "eval.episodes=2",
        "eval.final_episodes=2",
    )
    first, second = train_twice(train_cfg, tmp_path, *adr)
    assert "adr/entropy" in first["curves"]
    assert record_differences(first, second) == []


def _report_main():
    """The script's ``main`` (a script, not a module of the package: loaded by path)."""
    return runpy.run_path(str(ROOT / "scripts" / "adr_report.py"))["main"]


def test_the_report_sets_default_wide_and_the_adr_ranges_side_by_side(tmp_path: Path, capsys) -> None:
    sync = AdrSync(Randomizer(ADR_SPEC))
    sync.state.ranges["finger_force"] = [5.0, 60.0]
    ranges = sync.write_ranges(tmp_path)
    out = tmp_path / "report"
    assert _report_main()(["scripted", "--ranges", str(ranges), "--episodes", "2", "--out", str(out)]) == 0
    report = yaml.safe_load((out / "adr_report.json").read_text())
    assert list(report["conditions"]) == ["default", "wide", "adr ranges"]
    assert set(report["success"]["scripted"]) == {"default", "wide", "adr ranges"}
    assert report["success"]["scripted"]["wide"]["episodes"] == 2
    # finger_force [5, 60] contains default's [10, 40]; the nominal-only others mostly do not
    assert "finger_force" in report["contain_default"] and "object_mass" not in report["contain_default"]
    assert "| scripted" in capsys.readouterr().out


def test_the_report_refuses_a_missing_ranges_file_in_one_line(tmp_path: Path, capsys) -> None:
    assert _report_main()(["scripted", "--ranges", str(tmp_path / "nowhere.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --ranges") and "no such file" in err[0]
