"""Evaluation harness: artefacts from a checkpoint alone, baselines, worker-count invariance, bad input."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from rlgrasp.compose import compose_eval, compose_train
from rlgrasp.evaluation import EvaluationError
from rlgrasp.evaluation.cli import evaluate
from rlgrasp.evaluation.episodes import run_episodes
from rlgrasp.evaluation.metrics import summarize
from rlgrasp.evaluation.plots import binned_success
from rlgrasp.evaluation.source import build_env_cfg, prepare
from tests.helpers import make_run

ROOT = Path(__file__).resolve().parents[1]


def _cfg(*overrides: str):
    return compose_eval(list(overrides))


def test_a_run_judged_on_other_ranges_is_evaluated_on_them(tmp_path: Path) -> None:
    """A curriculum run judged on `default` (``eval.randomization``): evaluating its checkpoint plays
    `default` too, unless told otherwise; a run that did not choose plays its training ranges."""
    curriculum = ("randomization=adr_objects", "eval.randomization=default")
    run = make_run(tmp_path, overrides=curriculum)
    assert prepare("checkpoint", str(run)).env_cfg["randomization"] == "default"
    assert prepare("checkpoint", str(run), randomization="wide").env_cfg["randomization"] == "wide"
    own = prepare("checkpoint", str(make_run(tmp_path / "b", overrides=curriculum[:1])))
    assert own.env_cfg["randomization"]["adr"]["params"].keys() == {"object_size_scale", "object_mass"}


def test_checkpoint_evaluation_writes_every_artefact(tmp_path: Path) -> None:
    run = make_run(tmp_path)
    m = evaluate(_cfg(f"ckpt={run}", "episodes=4", "workers=1", "video_episodes=1", "name=t"))
    out = run / "eval" / "t"
    assert Path(m["output_dir"]) == out
    for f in (
        "metrics.json",
        "episodes.csv",
        "summary.md",
        "success_by_parameter.png",
        "return_histogram.png",
    ):
        assert (out / f).is_file(), f
    assert len(list(out.glob("episode_000_seed_0.*"))) == 1  # gif (mp4 if ffmpeg)
    saved = json.loads((out / "metrics.json").read_text())
    for key in ("success_at_end", "success_once"):
        assert set(saved[key]) == {"rate", "successes", "episodes", "ci95"}
    assert saved["seeds"] == [0, 1, 2, 3]
    assert (
        saved["checkpoint"]["path"].endswith("checkpoints/best.pt") and saved["checkpoint"]["frames"] == 4096
    )
    assert saved["config"]["train"]["experiment_name"] == "unit"
    assert saved["config"]["env"]["randomization"] == "default"  # from the checkpoint
    assert saved["config"]["env"]["_target_"] == "rlgrasp.envs.PandaGraspEnv"
    assert {"mean", "std"} <= set(saved["return"]) and saved["mean_length"] == 50.0
    rows = list(csv.DictReader(open(out / "episodes.csv")))
    assert [int(r["seed"]) for r in rows] == [0, 1, 2, 3]
    expected = {"object_mass", "finger_force", "object_x", "return", "success_at_end", "success_once"}
    assert expected <= set(rows[0])
    assert "success at end" in (out / "summary.md").read_text()
    assert list((run / "tensorboard").glob("events.out.tfevents.*"))  # logged to the run
    # ckpt_kind=last and explicit randomization ranges (conditions never trained on).
    m2 = evaluate(
        _cfg(
            f"ckpt={run}",
            "ckpt_kind=last",
            "episodes=2",
            "workers=1",
            "video=false",
            "plots=false",
            "tensorboard=false",
            "name=t2",
            "randomization={preset:none,object_mass:[0.8,1.0]}",
        )
    )
    assert m2["checkpoint"]["path"].endswith("last.pt")
    masses = [float(r["object_mass"]) for r in csv.DictReader(open(run / "eval" / "t2" / "episodes.csv"))]
    assert all(0.8 <= x <= 1.0 for x in masses)


def test_scripted_baseline_within_known_bounds(tmp_path: Path) -> None:
    """benchmarks/bench_expert.py: default preset 98/100 on seeds 0-99, so >= 18/20 on seeds 0-19."""
    m = evaluate(
        _cfg(
            "policy=scripted",
            "episodes=20",
            "workers=1",
            "video=false",
            "plots=false",
            f"outputs_root={tmp_path}",
            "name=s",
        )
    )
    assert m["success_at_end"]["successes"] >= 18
    assert m["success_at_end"]["ci95"][1] == 1.0 or m["success_at_end"]["ci95"][1] > 0.95
    assert (tmp_path / "eval" / "scripted" / "s" / "metrics.json").is_file()
    assert m["checkpoint"] is None and m["config"]["env"]["randomization"] == "default"


def test_random_baseline_rarely_succeeds(tmp_path: Path) -> None:
    m = evaluate(
        _cfg(
            "policy=random",
            "episodes=4",
            "workers=1",
            "video=false",
            "plots=false",
            f"outputs_root={tmp_path}",
            "name=r",
        )
    )
    assert m["success_at_end"]["successes"] == 0


@pytest.mark.full  # three evaluations, two with worker processes
def test_one_and_two_workers_identical_stochastic_policy(tmp_path: Path) -> None:
    """Episodes are seeded one by one: the split across processes must not change anything."""
    source = prepare("checkpoint", str(make_run(tmp_path)))
    one = run_episodes(source, episodes=5, base_seed=7, workers=1, deterministic=False)
    two = run_episodes(source, episodes=5, base_seed=7, workers=2, deterministic=False)
    assert summarize(one) == summarize(two)
    assert [(r.seed, r.episode_return, r.randomization) for r in one] == [
        (r.seed, r.episode_return, r.randomization) for r in two
    ]
    # Stochastic actions really differ from deterministic ones (the seeding is not a no-op).
    det = run_episodes(source, episodes=1, base_seed=7, workers=1, deterministic=True)
    assert det[0].episode_return != one[0].episode_return


# --- bad input: a clear error naming the problem, nothing written -----------------------------
def _assert_fails(tmp: Path, match: str, *overrides: str) -> None:
    before = sorted(p for p in tmp.rglob("*"))
    with pytest.raises(EvaluationError, match=match):
        evaluate(_cfg(*overrides, "episodes=1", "workers=1", f"outputs_root={tmp / 'outputs'}"))
    assert sorted(p for p in tmp.rglob("*")) == before


def test_missing_checkpoint(tmp_path: Path) -> None:
    _assert_fails(tmp_path, "missing checkpoint: .* does not exist", f"ckpt={tmp_path / 'nope.pt'}")
    run = make_run(tmp_path)
    (run / "checkpoints" / "best.pt").unlink()
    _assert_fails(tmp_path, r"no checkpoints/best.pt.*ckpt_kind=last", f"ckpt={run}")
    _assert_fails(tmp_path, "ckpt=<run dir", "policy=checkpoint")


def test_corrupt_checkpoint(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"\x00not a checkpoint" * 50)
    _assert_fails(tmp_path, "corrupt checkpoint", f"ckpt={garbage}")
    run = make_run(tmp_path)
    best = run / "checkpoints" / "best.pt"
    best.write_bytes(best.read_bytes()[:2000])  # truncated mid-write
    _assert_fails(tmp_path, "corrupt checkpoint", f"ckpt={run}")
    torch.save({"weights": 1}, best)
    _assert_fails(
        tmp_path, r"not an rlgrasp training checkpoint \(missing actor, config, spec", f"ckpt={run}"
    )


def test_layout_mismatch(tmp_path: Path) -> None:
    run = make_run(tmp_path, obs_dim=40)  # the env has 42
    _assert_fails(tmp_path, "observation layout mismatch: checkpoint obs_dim=40", f"ckpt={run}")
    run2 = make_run(tmp_path / "b")
    # joint_delta: 7 joint deltas + gripper = 8 actions, and a longer prev_action in the observation.
    _assert_fails(
        tmp_path,
        "action layout mismatch: checkpoint action_dim=4",
        f"ckpt={run2}",
        "+env.control.mode=joint_delta",
    )


@pytest.mark.full  # two interpreters; quick set: test_bad_input's eval cases
def test_cli_errors_exit_cleanly(tmp_path: Path) -> None:
    """Bad input: one line on stderr and exit code 2; an unknown key: Hydra's own error."""
    script = str(ROOT / "scripts" / "evaluate.py")
    bad = subprocess.run(
        [sys.executable, script, f"ckpt={tmp_path / 'missing'}"], capture_output=True, text=True, cwd=tmp_path
    )
    assert bad.returncode == 2 and "error: missing checkpoint" in bad.stderr and "Traceback" not in bad.stderr
    unknown = subprocess.run(
        [sys.executable, script, "episdoes=5"], capture_output=True, text=True, cwd=tmp_path
    )
    assert unknown.returncode == 1 and "episdoes" in unknown.stderr
    assert list(tmp_path.iterdir()) == []


def test_binned_success_intervals() -> None:
    values = np.arange(40, dtype=float)
    bins = binned_success(values, values >= 20, max_bins=4)
    assert [b["n"] for b in bins] == [10, 10, 10, 10]
    assert [b["rate"] for b in bins] == [0.0, 0.0, 1.0, 1.0]
    assert all(b["ci95"][0] <= b["rate"] <= b["ci95"][1] for b in bins)
    ints = binned_success(np.array([0, 1, 1, 0, 1]), np.array([1, 0, 0, 1, 1], bool))
    assert [(b["low"], b["n"], b["successes"]) for b in ints] == [(0.0, 2, 2), (1.0, 3, 1)]


@pytest.mark.slow
def test_evaluate_a_short_training_run(tmp_path: Path) -> None:
    """A real smoke training run, then its evaluation from the run directory alone."""
    from rlgrasp.train.loop import train

    run = tmp_path / "run"
    train(compose_train(["experiment=smoke", f"paths.output_dir={run}"]))
    m = evaluate(_cfg(f"ckpt={run}", "episodes=6", "workers=2", "video_episodes=1", "name=e"))
    assert m["episodes"] == 6 and (run / "eval" / "e" / "metrics.json").is_file()
    assert m["checkpoint"]["frames"] > 0


@pytest.mark.slow
def test_cli_metrics_identical_with_one_and_two_workers(tmp_path: Path) -> None:
    out = {}
    for w in (1, 2):
        m = evaluate(
            _cfg(
                "policy=scripted",
                "episodes=12",
                f"workers={w}",
                "video_episodes=1",
                f"outputs_root={tmp_path}",
                f"name=w{w}",
            )
        )
        out[w] = {
            k: v
            for k, v in m.items()
            if k not in ("timing", "config", "output_dir", "summary_markdown", "files")
        }
    assert out[1] == out[2]


def test_held_out_objects_and_randomization_are_named(tmp_path: Path) -> None:
    """A figure on other objects or conditions than training's says so, in metrics.json and in the
    summary (as the console header does); one under training's own conditions says that too."""
    run = make_run(tmp_path)
    m = evaluate(
        _cfg(
            f"ckpt={run}",
            "objects=primitives",
            "randomization=wide",
            "episodes=2",
            "video=false",
            "plots=false",
            "tensorboard=false",
            "name=held_out",
        )
    )
    assert m["objects_label"] == "primitives (trained on cube)"
    assert m["randomization_label"] == "wide (trained on default)"
    assert m["checkpoint"]["train_objects"] == "cube" and m["config"]["env"]["objects"] == "primitives"
    summary = (run / "eval" / "held_out" / "summary.md").read_text()
    assert summary.startswith("# Evaluation held_out\n")
    assert "| objects " in summary and "primitives (trained on cube)" in summary
    assert "wide (trained on default)" in summary
    same = evaluate(
        _cfg(
            f"ckpt={run}", "episodes=1", "video=false", "plots=false", "tensorboard=false", "name=as_trained"
        )
    )
    assert same["objects_label"] == "cube (as trained)"
    assert same["randomization_label"] == "default (as trained)"


@pytest.mark.parametrize("preset", ["none", "wide"])
def test_randomization_preset_by_name_reaches_the_env(tmp_path: Path, preset: str) -> None:
    """`randomization=wide` names a config group too; it must still set the evaluated env's preset."""
    cfg = _cfg(f"ckpt={make_run(tmp_path)}", f"randomization={preset}")
    source = prepare(cfg.policy, cfg.ckpt, cfg.ckpt_kind, None, OmegaConf.to_container(cfg.env))
    assert source.env_cfg["randomization"] == preset


def test_an_env_override_changes_one_keyword_of_the_checkpoints_part() -> None:
    """``env.control.ee_yaw=true`` keeps the checkpoint's control mode and ``env.task.air_fraction=0``
    its task (both were replaced whole: a pick-and-place checkpoint became the lift task, a
    joint_delta one ee_delta); a part of another class, and the robot or objects, are replaced."""
    place = {"_target_": "rlgrasp.envs.tasks.PickPlaceTask", "reward": "sparse", "air_fraction": 0.5}
    trained = {"_target_": "rlgrasp.envs.PandaGraspEnv", "task": place, "control": {"mode": "joint_delta"}}
    trained["objects"] = {"paths": ["a.obj"], "scale": [1.0, 1.0]}
    given = {"control": {"ee_yaw": True}, "task": {"air_fraction": 0.0}, "objects": {"paths": ["b.obj"]}}
    env = build_env_cfg(trained, None, given)
    assert env["control"]["mode"] == "joint_delta" and env["control"]["ee_yaw"] is True
    assert env["task"] == {**place, "air_fraction": 0.0}
    assert env["objects"] == {"paths": ["b.obj"]}
    other = {"_target_": "rlgrasp.envs.tasks.PushTask", "reward": "dense"}
    assert build_env_cfg(trained, None, {"task": other})["task"] == other
