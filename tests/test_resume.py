"""Resume: the checkpoint's config is the base, safe loading, unique run dirs, the fallback past a bad
last.pt, stop signals, resume=auto, and every entry point exiting."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

import rlgrasp
from rlgrasp import policy_file
from rlgrasp.compose import compose_train
from rlgrasp.config import ConfigError
from rlgrasp.evaluation.source import EvaluationError, load_checked_checkpoint
from rlgrasp.rundir import remove_refused_start, run_dir
from rlgrasp.train import checkpoint as ckpt_lib
from rlgrasp.train.loop import Trainer
from rlgrasp.train.resume import command_line_keys, merged_config, prepare_run
from rlgrasp.train.validate import validate_train
from tests.procs import wait_for

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ["experiment=smoke", "logger=none"]
COLLECTORS, LOGGERS = "rlgrasp.train.collection.collectors", "rlgrasp.train.tracking.logger"


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """A run directory with one real smoke checkpoint at frame 0 (no workers started)."""
    run = tmp_path_factory.mktemp("resume") / "run"
    Trainer(compose_train([*SMOKE, f"paths.output_dir={run}"])).save()
    return run


def test_rng_states_round_trip_through_a_weights_only_load(tmp_path: Path) -> None:
    random.seed(1), np.random.seed(2), torch.manual_seed(3)
    ckpt_lib.save_checkpoint(tmp_path / "x.pt", {"rng": ckpt_lib.rng_state()})
    want = (random.random(), np.random.rand(), torch.rand(1).item())
    ckpt_lib.set_rng_state(torch.load(tmp_path / "x.pt", weights_only=True)["rng"])
    assert (random.random(), np.random.rand(), torch.rand(1).item()) == want


class _Evil:
    """Unpickling this creates a file: what a malicious checkpoint would do."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def test_a_checkpoint_that_would_run_code_is_refused_and_runs_nothing(tmp_path: Path, run: Path) -> None:
    marker = tmp_path / "pwned"
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    state["payload"] = _Evil(str(marker))
    evil = tmp_path / "evil.pt"
    torch.save(state, evil, pickle_protocol=2)
    with pytest.raises(policy_file.CheckpointError, match="refused checkpoint"):
        policy_file.read_checkpoint(evil)
    with pytest.raises(EvaluationError, match="refused checkpoint"):
        load_checked_checkpoint(evil)
    assert not marker.exists()
    with open(evil, "rb"):  # the crafted file does work on a plain unpickler (control)
        torch.load(evil, weights_only=False)
    assert marker.exists()


def test_resume_alone_continues_the_run_as_launched(run: Path) -> None:
    # The default config (hidden sizes 256) plus resume= and total_frames: the smoke run's own config.
    cfg = compose_train([f"paths.output_dir={run}", f"resume={run}", "total_frames=4096", "device=cpu"])
    merged, state = prepare_run(cfg, changed={"resume", "total_frames", "device"})
    assert state["frames"] == 0
    assert list(merged.model.hidden_sizes) == [64, 64]
    assert merged.total_frames == 4096 and merged.device == "cpu"
    assert merged.experiment_name == "smoke"


def test_resume_refuses_a_change_of_a_fixed_key_naming_both_values(run: Path) -> None:
    saved = policy_file.load_checkpoint(run)["config"]
    cfg = compose_train([*SMOKE, f"paths.output_dir={run}", "env.control.mode=joint_delta"])
    with pytest.raises(
        ConfigError,
        match=r"env.control.mode: the checkpoint has 'ee_delta', the command "
        r"line 'joint_delta'",
    ):
        merged_config(cfg, saved, {"env.control.mode"})
    cfg = compose_train([*SMOKE, f"paths.output_dir={run}", "randomization=wide"])
    with pytest.raises(ConfigError, match="env.randomization"):
        merged_config(cfg, saved, {"env.randomization"})


def test_resume_refuses_a_group_choice_that_equals_the_default(run: Path) -> None:
    """``robot=panda`` changes no key from the defaults, yet on an iiwa run it asks for another arm."""
    saved = policy_file.load_checkpoint(run)["config"]
    saved["env"]["robot"] = "kuka_iiwa"
    for line, arm in ((["robot=panda"], None), ([], "kuka_iiwa"), (["robot=kuka_iiwa"], "kuka_iiwa")):
        overrides = [*SMOKE, f"paths.output_dir={run}", f"resume={run}", *line]
        cfg = compose_train(overrides)
        changed = command_line_keys(overrides, cfg)
        if arm is None:
            with pytest.raises(
                ConfigError,
                match="^cannot change on resume: env.robot: the checkpoint has "
                "'kuka_iiwa', the command line 'panda';",
            ) as info:
                merged_config(cfg, saved, changed)
            assert "\n" not in str(info.value)
        else:
            assert merged_config(cfg, saved, changed).env.robot == arm


def test_resume_may_switch_the_collector_and_logger_classes(run: Path) -> None:
    """collector=ray on a process run brings the Ray keys; back to process drops them again (the
    process backend would refuse them); logger=none replaces TensorBoard."""
    saved = policy_file.load_checkpoint(run)["config"]
    cfg = compose_train([*SMOKE, f"paths.output_dir={run}", "collector=ray", "collector.ray.address=auto"])
    to_ray = merged_config(cfg, saved, {"collector._target_", "collector.ray.address"})
    assert to_ray.collector._target_ == "rlgrasp.train.collection.collectors.RayCollector"
    assert to_ray.collector.ray.address == "auto"
    cfg = compose_train([*SMOKE, f"paths.output_dir={run}", "collector=process", "logger=tensorboard"])
    back = merged_config(cfg, OmegaConf.to_container(to_ray), {"collector._target_", "logger._target_"})
    assert back.collector._target_.endswith("ProcessCollector") and "ray" not in back.collector
    assert back.logger._target_.endswith("TensorBoardLogger")
    validate_train(back)


def test_a_checkpoint_with_string_backends_resumes(tmp_path: Path, run: Path) -> None:
    """Checkpoints from before the _target_ nodes (policies/*.pt among them) name the collector and
    the logger with strings; read, they come in today's shape, and resume, with the command line's
    logger (a file never chooses where the curves go, rlgrasp.received)."""
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    collector = {k: v for k, v in state["config"]["collector"].items() if k != "_target_"}
    state["config"]["collector"] = {"backend": "process", **collector, "ray": {"address": None}}
    state["config"]["logger"] = {"backend": "none", "console_interval_s": 5.0}
    old = tmp_path / "old" / "checkpoints" / "last.pt"
    ckpt_lib.save_checkpoint(old, state)
    cfg = compose_train([f"paths.output_dir={old.parents[1]}", f"resume={old}"])
    merged, resumed = prepare_run(cfg, {"resume"})
    assert resumed is not None
    assert dict(merged.collector) == {"_target_": f"{COLLECTORS}.ProcessCollector", **collector}
    assert merged.logger == cfg.logger and merged.logger._target_ != f"{LOGGERS}.ConsoleLogger"
    for shipped in sorted((ROOT / "policies").glob("*.pt")):
        config = policy_file.read_checkpoint(shipped)["config"]
        assert config["collector"]["_target_"] == f"{COLLECTORS}.ProcessCollector"
        assert "backend" not in config["collector"] and "ray" not in config["collector"]
        assert config["logger"] == {"name": "tensorboard"}  # what it used, as a name; nothing to build


def test_a_checkpoint_with_the_algorithm_state_at_the_top_level_resumes(tmp_path: Path, run: Path) -> None:
    """PPO's (and DAgger's) state sat beside the core's entries before each algorithm had its own key:
    such a checkpoint resumes with the same critic and optimizer, and today's writes it under ``ppo``."""
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert set(state["ppo"]) >= {"critic", "optimizer"} and "critic" not in state
    old_state = {k: v for k, v in state.items() if k != "ppo"} | state["ppo"]
    old = tmp_path / "old" / "checkpoints" / "last.pt"
    ckpt_lib.save_checkpoint(old, old_state)
    cfg, resumed = prepare_run(compose_train([*SMOKE, f"paths.output_dir={old.parents[1]}", f"resume={old}"]))
    trainer = Trainer(cfg, resumed=resumed)
    critic = trainer.algo.critic.state_dict()
    assert all(torch.equal(critic[k], v) for k, v in state["ppo"]["critic"].items())
    assert "critic" in trainer.state_dict()["ppo"] and "critic" not in trainer.state_dict()
    trainer.logger.close()


def test_a_checkpoint_naming_an_algorithm_by_an_older_class_path_reads_as_todays(run: Path) -> None:
    """DAgger's class moved into its package (rlgrasp.algos.dagger); a file naming the old path, and one
    naming no class (only ``algo.name``), are read back into the registry's class."""
    from rlgrasp.received import read_config

    config = torch.load(run / "checkpoints" / "last.pt", weights_only=True)["config"]
    old = {**config, "algo": {"_target_": "rlgrasp.vision.distill.DAgger", "name": "distill"}}
    assert read_config(old, "old.pt")["algo"]["_target_"] == "rlgrasp.algos.dagger.DAgger"
    unnamed = {**config, "algo": {k: v for k, v in config["algo"].items() if k != "_target_"}}
    assert read_config(unnamed, "old.pt")["algo"]["_target_"] == "rlgrasp.algos.ppo.PPO"


def test_a_requeued_slurm_job_resumes_its_run_dir_without_resume_given(run: Path, monkeypatch) -> None:
    """The requeued job runs its first command line again (no resume=) in a run dir with checkpoints."""
    cfg = compose_train([*SMOKE, f"paths.output_dir={run}"])
    monkeypatch.delenv("SLURM_RESTART_COUNT", raising=False)
    with pytest.raises(ConfigError, match="already holds checkpoints"):  # a first start: refused
        prepare_run(cfg)
    monkeypatch.setenv("SLURM_RESTART_COUNT", "1")
    merged, state = prepare_run(cfg)
    assert state is not None and state["frames"] == 0
    assert merged.resume == "auto"
    monkeypatch.setenv("SLURM_RESTART_COUNT", "0")
    with pytest.raises(ConfigError, match="already holds checkpoints"):
        prepare_run(cfg)


def test_a_truncated_last_falls_back_with_a_warning(tmp_path: Path, run: Path, caplog) -> None:
    copy = tmp_path / "run"
    (copy / "checkpoints").mkdir(parents=True)
    data = (run / "checkpoints" / "last.pt").read_bytes()
    (copy / "checkpoints" / "ckpt_0000000000.pt").write_bytes(data)
    (copy / "checkpoints" / "last.pt").write_bytes(data[:1000])  # a full disk
    path, state = policy_file.newest_readable(copy)
    assert path.name == "ckpt_0000000000.pt" and state["frames"] == 0
    assert "last.pt" in caplog.text
    assert run_dir(str(copy / "checkpoints" / "ckpt_0000000000.pt"), "x", 0) == str(copy)


def test_run_dirs_are_unique_per_process_and_name_the_seed(tmp_path: Path) -> None:
    code = "from rlgrasp.rundir import run_dir; print(run_dir(None, 'base', 7))"
    names = {
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
        ).stdout.strip()
        for _ in range(2)
    }
    assert len(names) == 2
    assert all(n.startswith("base/") and "_s7_" in n for n in names)


def test_a_refused_start_removes_the_folders_it_created_and_nothing_else(tmp_path: Path) -> None:
    (tmp_path / "outputs" / "train" / "other").mkdir(parents=True)  # another experiment's runs
    for base, gone, kept in (
        ("outputs/train/new", "outputs/train/new", "outputs/train/other"),
        ("fresh/train/new", "fresh", "outputs"),
    ):
        chosen = Path(run_dir(None, str(tmp_path / base), 0))
        (chosen / ".hydra").mkdir(parents=True)  # what Hydra writes before the start is refused
        remove_refused_start(chosen)
        assert not (tmp_path / gone).exists() and (tmp_path / kept).is_dir()


def test_resume_auto_picks_the_newest_run_of_the_seed(tmp_path: Path, run: Path) -> None:
    base = tmp_path / "smoke"
    assert "_s0_" in run_dir("auto", str(base), 0)  # nothing yet: a new run
    for name in (
        "2026-01-01_00-00-00_s0_aaaaaa",
        "2026-01-02_00-00-00_s0_bbbbbb",
        "2026-01-03_00-00-00_s1_cccccc",
    ):
        (base / name / "checkpoints").mkdir(parents=True)
        (base / name / "checkpoints" / "last.pt").write_bytes(b"")
    assert run_dir("auto", str(base), 0).endswith("2026-01-02_00-00-00_s0_bbbbbb")
    assert run_dir("auto", str(base), 1).endswith("_s1_cccccc")


def test_gym_make_honours_max_episode_steps() -> None:
    for kwargs, want in (({}, 50), ({"max_episode_steps": 80}, 80)):
        env = gym.make(rlgrasp.ENV_ID, randomization="none", **kwargs)
        env.reset(seed=0)
        steps = 0
        while True:
            steps += 1
            *_, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, np.float32))
            if terminated or truncated:
                break
        env.close()
        assert (steps, truncated) == (want, True)


# --- through the command line -------------------------------------------------------------------
def _train(args: list[str], cwd: Path, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, str(ROOT / "scripts" / "train.py"), *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        **kw,
    )


@pytest.mark.full  # three training processes per signal
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGUSR1])
def test_stop_signal_saves_then_resume_auto_finishes_and_exits(tmp_path: Path, sig: int) -> None:
    """A stop signal saves a checkpoint and exits 0; the same command (resume=auto) continues the run
    to the end; resuming the finished run exits at once (no hang at interpreter exit)."""
    cmd = [
        *SMOKE,
        "resume=auto",
        f"paths.root_dir={tmp_path}",
        "total_frames=4096",
        "checkpoint.interval_frames=100000",
        "eval.interval_frames=100000",
    ]
    proc = _train(cmd, tmp_path)
    try:
        runs = tmp_path / "outputs" / "train" / "smoke"
        log = wait_for(lambda: next(runs.glob("*/train.log"), None), 120)
        wait_for(lambda: True if "frames 1,024/" in log.read_text() else None, 180)
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, out[-2000:]
    run = log.parent
    assert f"{signal.Signals(sig).name} at" in out
    stopped = policy_file.load_checkpoint(run)["frames"]
    assert 1024 <= stopped < 4096  # saved on the signal, long before any interval checkpoint
    for expect_frames in (4096, 4096):  # resume=auto: continue; then: already finished
        t0 = time.monotonic()
        proc = _train(cmd, tmp_path)
        out, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, out[-2000:]
        assert policy_file.load_checkpoint(run)["frames"] == expect_frames
        assert "finished at 4,096 frames" in out
    assert time.monotonic() - t0 < 60  # the finished run starts no workers and exits
    assert len(list((tmp_path / "outputs" / "train" / "smoke").iterdir())) == 1


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_a_resume_keeps_the_launch_config_in_dot_hydra(tmp_path: Path) -> None:
    """Hydra writes each start's config and overrides; a later start in the run (resume, requeue) goes
    to .hydra/resume_<n>/, so .hydra/ keeps the launch's. A refused resume leaves no resume_<n>."""
    run = tmp_path / "run"
    tiny = [
        "collector=single",
        "collector.envs_per_worker=1",
        "collector.steps_per_env=16",
        "algo.optim.minibatch_size=16",
        "eval.episodes=1",
        "eval.final_episodes=1",
        "eval.num_envs=1",
    ]
    for args, code in (
        ([*SMOKE, *tiny, f"hydra.run.dir={run}", "total_frames=16"], 0),
        ([f"resume={run}", "total_frames=32"], 0),
        ([f"resume={run}", "algo.loss.gamma=0.5"], 2),
    ):
        proc = _train(args, tmp_path)
        out, _ = proc.communicate(timeout=300)
        assert proc.returncode == code and "Traceback" not in out, out[-2000:]
    hydra = run / ".hydra"
    assert "total_frames: 16\n" in (hydra / "config.yaml").read_text()
    assert "resume" not in (hydra / "overrides.yaml").read_text()
    assert sorted(p.name for p in hydra.iterdir() if p.is_dir()) == ["resume_1"]
    assert "total_frames=32" in (hydra / "resume_1" / "overrides.yaml").read_text()
    assert {p.name for p in (hydra / "resume_1").iterdir()} == {"config.yaml", "hydra.yaml", "overrides.yaml"}
    assert policy_file.load_checkpoint(run)["frames"] == 32


@pytest.mark.slow
def test_soak_three_kill_9_cycles(tmp_path: Path) -> None:
    """benchmarks/soak_resume.py: 3 x (start or resume, random wait, kill -9 of the group), every check."""
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "soak_resume.py"),
            "--cycles",
            "3",
            "--out",
            str(tmp_path),
            "--wait",
            "15",
            "35",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "PASSED" in proc.stdout
