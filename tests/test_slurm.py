"""hydra/launcher=slurm on a real SLURM cluster: the one-node cluster of scripts/local_slurm.sh (which
.ci/run starts when it can) or any cluster sinfo reaches. Without one, the cluster tests skip and
say why; the sizing test needs no cluster."""

from __future__ import annotations

import os
import pickle
import re
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
import torch

from tests.procs import wait_for

ROOT = Path(__file__).resolve().parents[1]
# In-process collection (collector.num_workers=0: one CPU per job), so both seeds run at once on two cores.
IN_PROCESS = ["collector=single", "collector.num_workers=0", "collector.envs_per_worker=4"]
TINY = [*IN_PROCESS, "total_frames=1024", "logger=none"]


def _launcher_params(*overrides: str) -> dict:
    """The parameters the SLURM launcher hands to submitit for this command line."""
    from hydra import compose, initialize_config_dir
    from hydra.core.plugins import Plugins

    from rlgrasp.config import CONFIG_DIR, register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train", overrides=["hydra/launcher=slurm", *overrides], return_hydra_config=True)
        launcher = Plugins.instance()._instantiate(cfg.hydra.launcher)
    return launcher.params


def _sbatch_lines(params: dict) -> list[str]:
    """The #SBATCH lines submitit would write for these launcher parameters."""
    from submitit.slurm.slurm import _make_sbatch_string

    keys = ("partition", "account", "cpus_per_task", "mem_per_cpu", "nodes", "setup")
    kwargs = {k: params[k] for k in keys if params.get(k) is not None}
    if params.get("mem_gb") is not None:
        kwargs["mem"] = f"{params['mem_gb']}GB"
    text = _make_sbatch_string(command="true", folder="/tmp/x", ntasks_per_node=params["tasks_per_node"],
                               **kwargs)
    return [line for line in text.splitlines() if line.startswith("#SBATCH")]


@pytest.mark.parametrize(
    ("overrides", "cpus"),
    [
        (["experiment=smoke"], 3),                                   # 2 workers + the learner
        (["experiment=smoke", "collector.num_workers=3"], 4),
        (["experiment=grasp_ppo", "collector.num_workers=8"], 9),
        (["collector=single", "collector.num_workers=0"], 1),        # in-process collection
        (["experiment=smoke", "hydra.launcher.cpus_per_task=2"], 2),  # an explicit value wins
    ],
)
def test_slurm_launcher_sizes_the_job_from_the_training_config(overrides: list[str], cpus: int) -> None:
    params = _launcher_params(*overrides)
    assert params["cpus_per_task"] == cpus
    assert params["mem_per_cpu"] == "2G" and params["mem_gb"] is None
    lines = _sbatch_lines(params)
    assert f"#SBATCH --cpus-per-task={cpus}" in lines
    assert "#SBATCH --mem-per-cpu=2G" in lines
    assert not any(line.startswith("#SBATCH --mem=") for line in lines)
    assert not any("partition" in line or "account" in line for line in lines)  # the cluster's defaults


def test_slurm_launcher_partition_account_and_total_memory_are_overridable() -> None:
    params = _launcher_params("experiment=smoke", "hydra.launcher.partition=gpu",
                              "hydra.launcher.account=lab", "hydra.launcher.mem_per_cpu=null",
                              "hydra.launcher.mem_gb=8")
    lines = _sbatch_lines(params)
    assert {"#SBATCH --partition=gpu", "#SBATCH --account=lab", "#SBATCH --mem=8GB"} <= set(lines)
    assert not any(line.startswith("#SBATCH --mem-per-cpu") for line in lines)


@pytest.mark.parametrize(
    ("shown_restarts", "env_restarts", "exits"),
    [
        (1, None, True),    # first run, SLURM requeued it (scontrol requeue): pending again
        (2, "1", True),     # the same in the rerun
        (0, None, False),   # not requeued (submitit refused, e.g. timed out too often): the job ends
        (1, "1", False),
    ],
)
def test_a_job_slurm_requeued_itself_exits_without_a_result(
    tmp_path: Path, monkeypatch, shown_restarts: int, env_restarts: str | None, exits: bool
) -> None:
    """After `scontrol requeue` SLURM signals a job it already requeued; submitit's own requeue then
    fails ("Job is pending execution"). Returning would write a submitit result with the preempted
    frames, and the sweep would take it for the run's end; exiting leaves the result to the rerun."""
    import signal

    from rlgrasp.train.preemption import hand_off_preemption

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "scontrol").write_text(
        f"#!/bin/sh\necho 'JobId=7 JobState=COMPLETING Reason=None Restarts={shown_restarts}'\n")
    (bin_dir / "scontrol").chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("SLURM_JOB_ID", "7")
    if env_restarts is None:
        monkeypatch.delenv("SLURM_RESTART_COUNT", raising=False)
    else:
        monkeypatch.setenv("SLURM_RESTART_COUNT", env_restarts)
    calls = []

    def checkpoint_and_try_requeue(signum: int, frame: object) -> None:  # submitit's handler's name
        calls.append(signum)
        raise subprocess.CalledProcessError(1, ["scontrol", "requeue", "7"])

    if exits:
        with pytest.raises(SystemExit):
            hand_off_preemption(signal.SIGTERM, {signal.SIGTERM: checkpoint_and_try_requeue})
    else:
        hand_off_preemption(signal.SIGTERM, {signal.SIGTERM: checkpoint_and_try_requeue})
    assert calls == [signal.SIGTERM]


# ---------------------------------------------------------------------------------------------
# On a cluster


def _cluster_problem() -> str | None:
    """Why SLURM jobs cannot run here, or None when a partition has a usable node."""
    if shutil.which("sinfo") is None:
        return "no sinfo on PATH (start a local cluster: sudo bash scripts/local_slurm.sh start)"
    try:
        proc = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        return "sinfo did not answer within 30 s"
    states = proc.stdout.split()
    if proc.returncode != 0 or not states:
        return f"no SLURM controller answers ({(proc.stderr.strip() or 'sinfo failed')[:200]})"
    if not {"idle", "mixed", "allocated", "completing"} & set(states):
        return f"no usable SLURM node (states: {', '.join(sorted(set(states)))})"
    return None


@pytest.fixture(scope="module")
def slurm() -> None:
    problem = _cluster_problem()
    if problem:
        # A warning as well as the skip: the warnings summary is printed without -rs.
        warnings.warn(f"SLURM tests skipped: {problem}", stacklevel=1)
        pytest.skip(problem)


def _job_env() -> dict[str, str]:
    """The submitting process's environment reaches the job (sbatch exports it); the job's setup line
    activates RLGRASP_VENV, here the interpreter running the tests."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path, "RLGRASP_VENV": sys.prefix}


def _scontrol_job(job_id: str) -> dict[str, str]:
    out = subprocess.run(["scontrol", "-o", "show", "job", job_id], capture_output=True, text=True,
                         check=True, timeout=30).stdout
    return dict(re.findall(r"(\w+)=(\S*)", out))


def _ended_job(job_id: str, timeout: float = 60) -> dict[str, str]:
    """scontrol's record of the job once it has ended (Hydra returns as soon as the result file
    exists; the job itself ends a moment later)."""
    deadline = time.monotonic() + timeout
    while True:
        info = _scontrol_job(job_id)
        if info["JobState"] not in ("PENDING", "RUNNING", "COMPLETING") or time.monotonic() > deadline:
            return info
        time.sleep(0.5)


def test_two_seed_multirun_on_slurm(slurm, tmp_path: Path) -> None:
    """Two seeds as a SLURM job array through hydra/launcher=slurm, sized by the config (1 CPU each)."""
    start = time.monotonic()
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "train.py"), "-m", "hydra/launcher=slurm", "experiment=smoke",
         "seed=0,1", f"paths.root_dir={tmp_path}", "hydra.launcher.timeout_min=10", *TINY],
        capture_output=True, text=True, cwd=tmp_path, env=_job_env(), timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    (sweep_dir,) = (tmp_path / "outputs" / "multirun" / "smoke").iterdir()
    jobs = sorted(p for p in sweep_dir.iterdir() if p.is_dir() and p.name.isdigit())
    assert [j.name for j in jobs] == ["0", "1"]
    slurm_ids = set()
    for seed, job in enumerate(jobs):
        assert f"seed={seed}" in (job / ".hydra" / "overrides.yaml").read_text()
        ckpt = torch.load(job / "checkpoints" / "last.pt", map_location="cpu", weights_only=False)
        assert ckpt["frames"] == 1024
        assert "finished at" in (job / "train.log").read_text()
        # The job id submitit saw inside the job: <array id>_<task>, a SLURM array task.
        (job_id,) = re.findall(r"^\s+id: '?(\d+_\d+)'?$", (job / ".hydra" / "hydra.yaml").read_text(), re.M)
        assert job_id.endswith(f"_{seed}")
        slurm_ids.add(job_id.split("_")[0])
        info = _ended_job(job_id)
        assert info["JobState"] == "COMPLETED", info
        assert info["NumCPUs"] == "1", info  # collector.num_workers=0 + the learner
        assert info["MinMemoryCPU"] in ("2G", "2048M"), info
    assert len(slurm_ids) == 1  # one array
    results = list((sweep_dir / ".submitit").glob("*/*_result.pkl"))
    assert len(results) == 2
    for path in results:
        status, value = pickle.loads(path.read_bytes())
        assert status == "success"
        assert isinstance(value.return_value, float)
    print(f"two-seed SLURM multirun: {time.monotonic() - start:.1f} s")


@pytest.mark.slow
@pytest.mark.parametrize("how", ["requeue", "sigterm"])
def test_preempted_job_resumes_in_its_run_dir(slurm, tmp_path: Path, how: str) -> None:
    """Preempt a running job with `scontrol requeue` (SLURM requeues it, then sends SIGTERM) or with
    `scancel --signal=TERM` (the training process gets SIGTERM and submitit's handler requeues the
    job): it saves a checkpoint, runs its command line again (no resume= given) in the same job dir,
    continues from that checkpoint and ends with the frames of an uninterrupted run."""
    frames = 8192
    # timeout_min over 10: submitit takes any signal in a job of at most 10 minutes for its time limit
    # (it guarantees min(0.8 T, T - 10 min) of walltime) and, with max_num_timeout=0, does not requeue.
    proc = subprocess.Popen(
        [sys.executable, str(ROOT / "scripts" / "train.py"), "-m", "hydra/launcher=slurm", "experiment=smoke",
         "seed=0", f"paths.root_dir={tmp_path}", f"total_frames={frames}", "checkpoint.interval_frames=1024",
         "eval.interval_frames=4096", "hydra.launcher.timeout_min=30", "logger=none", *IN_PROCESS],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path, env=_job_env(),
    )
    try:
        sweeps = tmp_path / "outputs" / "multirun" / "smoke"
        job = wait_for(lambda: next(sweeps.glob("*/0/checkpoints/last.pt"), None), timeout=300).parents[1]
        (job_id,) = re.findall(r"^\s+id: '?(\d+(?:_\d+)?)'?$", (job / ".hydra" / "hydra.yaml").read_text(),
                               re.M)
        if how == "requeue":
            subprocess.run(["scontrol", "requeue", job_id], check=True, timeout=30)
        else:
            subprocess.run(["scancel", "--signal=TERM", job_id], check=True, timeout=30)
        # SLURM holds a requeued job for ~2 minutes (Reason=BeginTime); let it start as soon as it is pending.
        wait_for(lambda: True if _scontrol_job(job_id)["JobState"] == "PENDING" else None, timeout=120)
        subprocess.run(["scontrol", "update", f"JobId={job_id}", "StartTime=now"], check=True, timeout=30)
        out, _ = proc.communicate(timeout=600)
    finally:
        proc.kill()
    assert proc.returncode == 0, out[-3000:]
    ckpt = torch.load(job / "checkpoints" / "last.pt", map_location="cpu", weights_only=False)
    assert ckpt["frames"] == frames
    assert ckpt["generation"] >= 1  # resumed at least once
    log = (job / "train.log").read_text()
    (stopped,) = re.findall(r"SIGTERM at ([\d,]+) frames: saving a checkpoint", log)
    (resumed,) = re.findall(r"resumed from auto at ([\d,]+) frames", log)
    assert resumed == stopped and 0 < int(stopped.replace(",", "")) < frames  # from the signal's checkpoint
    assert log.count("finished at") == 1
    assert int(_scontrol_job(job_id).get("Restarts", "0")) >= 1
    # One result, the rerun's: the preempted run wrote none (it would have ended the sweep early).
    (result,) = (job.parent / ".submitit").glob("*/*_result.pkl")
    status, value = pickle.loads(result.read_bytes())
    assert status == "success" and isinstance(value.return_value, float)

