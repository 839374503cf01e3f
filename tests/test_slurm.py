"""hydra/launcher=slurm on a real SLURM cluster: the one-node cluster of scripts/local_slurm.sh (which
.ci/run starts when it can) or any cluster sinfo reaches. Without one, the cluster tests skip and
say why; the sizing test needs no cluster."""

from __future__ import annotations

import os
import pickle
import re
import shutil
import signal
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
    text = _make_sbatch_string(
        command="true", folder="/tmp/x", ntasks_per_node=params["tasks_per_node"], **kwargs
    )
    return [line for line in text.splitlines() if line.startswith("#SBATCH")]


@pytest.mark.parametrize(
    ("overrides", "cpus"),
    [
        (["experiment=smoke"], 3),  # 2 workers + the learner
        (["experiment=smoke", "collector.num_workers=3"], 4),
        (["experiment=grasp_ppo", "collector.num_workers=8"], 9),
        (["collector=single", "collector.num_workers=0"], 1),  # in-process collection
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
    params = _launcher_params(
        "experiment=smoke",
        "hydra.launcher.partition=gpu",
        "hydra.launcher.account=lab",
        "hydra.launcher.mem_per_cpu=null",
        "hydra.launcher.mem_gb=8",
    )
    lines = _sbatch_lines(params)
    assert {"#SBATCH --partition=gpu", "#SBATCH --account=lab", "#SBATCH --mem=8GB"} <= set(lines)
    assert not any(line.startswith("#SBATCH --mem-per-cpu") for line in lines)


@pytest.mark.parametrize(
    ("shown_restarts", "env_restarts", "exits"),
    [
        (1, None, True),  # first run, SLURM requeued it (scontrol requeue): pending again
        (2, "1", True),  # the same in the rerun
        (0, None, False),  # not requeued (submitit refused, e.g. timed out too often): the job ends
        (1, "1", False),
    ],
)
def test_a_job_slurm_requeued_itself_exits_without_a_result(
    tmp_path: Path, monkeypatch, shown_restarts: int, env_restarts: str | None, exits: bool
) -> None:
    """After `scontrol requeue` SLURM signals a job it already requeued; submitit's own requeue then
    fails ("Job is pending execution"). Returning would write a submitit result with the preempted
    frames, and the sweep would take it for the run's end; exiting leaves the result to the rerun."""

    from rlgrasp.train.preemption import hand_off_preemption

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "scontrol").write_text(
        f"#!/bin/sh\necho 'JobId=7 JobState=COMPLETING Reason=None Restarts={shown_restarts}'\n"
    )
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
# Can it ever run? (sinfo text, no cluster)

SINFO = """\
vm|2|21694|debug*|infinite|(null)
big1|32|257000|long|7-00:00:00|(null)
big2|32|128000|long|7-00:00:00|(null)
g1|16|64000|gpu|2:00:00|gpu:a100:4(S:0-1)
"""


def test_sinfo_lines_become_nodes() -> None:
    from rlgrasp.slurm import Node, parse_sinfo

    nodes = parse_sinfo(SINFO + "garbage line\n")
    assert nodes[0] == Node("vm", "debug", True, 2, 21694, 0, None)
    assert nodes[1] == Node("big1", "long", False, 32, 257000, 0, 7 * 1440)
    assert (nodes[3].gpus, nodes[3].max_time_min, nodes[3].default) == (4, 120, False)
    assert len(nodes) == 4


@pytest.mark.parametrize(
    ("text", "minutes"),
    [
        ("infinite", None),
        ("UNLIMITED", None),
        ("30", 30),
        ("30:30", 30.5),
        ("2:00:00", 120),
        ("1-12", 36 * 60),
        ("1-00:30", 1470),
        ("2-00:00:30", 2880.5),
    ],
)
def test_slurm_time_limits_in_minutes(text: str, minutes: float | None) -> None:
    from rlgrasp.slurm import slurm_minutes

    assert slurm_minutes(text) == minutes


def _params(**overrides) -> dict:
    """The launcher parameters slurm.yaml gives the smoke experiment (2 workers + the learner)."""
    return {
        "partition": None,
        "cpus_per_task": 3,
        "tasks_per_node": 1,
        "nodes": 1,
        "mem_per_cpu": "2G",
        "mem_gb": None,
        "gpus_per_node": None,
        "gpus_per_task": None,
        "gres": None,
        "timeout_min": 240,
        **overrides,
    }


def test_a_job_bigger_than_any_node_is_refused_in_one_line_naming_the_key_and_the_fix() -> None:
    from rlgrasp.slurm import refusal

    line = refusal(_params(), SINFO, workers=2)
    assert line == (
        "error: SLURM partition debug can never run this job: hydra.launcher.cpus_per_task=3 "
        "(collector.num_workers=2 + 1 for the learner) asks for 3 CPUs per node, its nodes have "
        "at most 2; use collector.num_workers=1 or hydra.launcher.cpus_per_task=2"
    )
    # cpus_per_task given as a number: the workers are not what sizes the job, so not the fix
    line = refusal(_params(), SINFO, workers=None)
    assert "collector.num_workers" not in line and line.endswith("use hydra.launcher.cpus_per_task=2")


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        # memory judged for the CPUs a node can give; per CPU or in total
        (
            {"cpus_per_task": 2, "mem_per_cpu": "12G"},
            "hydra.launcher.mem_per_cpu=12G x 2 CPUs asks for 24.0 GB per node, its nodes have at most "
            "21.2 GB (21694 MB); use hydra.launcher.mem_per_cpu=10847M",
        ),
        (
            {"cpus_per_task": 1, "mem_per_cpu": None, "mem_gb": 64},
            "hydra.launcher.mem_gb=64 asks for 64.0 GB per node, its nodes have at most 21.2 GB (21694 MB); "
            "use hydra.launcher.mem_gb=21",
        ),
        (
            {"cpus_per_task": 1, "gpus_per_node": 1},
            "hydra.launcher.gpus_per_node=1 asks for 1 GPU(s) per node, "
            "its nodes have none; use a partition with GPUs (hydra.launcher.partition=<name>)",
        ),
        (
            {"cpus_per_task": 1, "nodes": 2},
            "hydra.launcher.nodes=2: only 1 of its nodes have 1 CPUs, 2.0 GB; use hydra.launcher.nodes=1",
        ),
    ],
)
def test_each_resource_is_compared_with_the_partitions_nodes(overrides: dict, expected: str) -> None:
    from rlgrasp.slurm import refusal

    line = refusal(_params(**overrides), SINFO)
    assert line == f"error: SLURM partition debug can never run this job: {expected}"


def test_partition_names_and_time_limits_are_checked() -> None:
    from rlgrasp.slurm import refusal

    assert refusal(_params(partition="gpus"), SINFO) == (
        "error: hydra.launcher.partition=gpus: no SLURM partition gpus; sinfo lists debug, long, gpu"
    )
    assert refusal(_params(partition="gpu", gpus_per_node=2), SINFO) == (
        "error: SLURM partition gpu can never run this job: hydra.launcher.timeout_min=240: its time limit "
        "is 120 min; use hydra.launcher.timeout_min=120"
    )
    assert "no default partition" in refusal(_params(), SINFO.replace("debug*", "debug"))


@pytest.mark.parametrize(
    "overrides",
    [
        {"cpus_per_task": 2},  # fits the default partition
        {"partition": "long", "cpus_per_task": 32, "mem_per_cpu": "4000M", "nodes": 2},
        {"partition": "gpu", "gres": "gpu:a100:4", "timeout_min": 120},
        {"partition": "debug,long", "cpus_per_task": 8},  # sbatch takes the first that can
    ],
)
def test_a_job_some_node_can_run_is_not_refused(overrides: dict) -> None:
    from rlgrasp.slurm import refusal

    assert refusal(_params(**overrides), SINFO) is None


def test_a_mixed_partition_needs_one_node_with_everything_at_once() -> None:
    from rlgrasp.slurm import refusal

    # big1 has the memory, big2 too few; 2 nodes of 200 GB: only one has it
    line = refusal(_params(partition="long", cpus_per_task=32, mem_per_cpu="6400M", nodes=2), SINFO)
    assert line.endswith(
        "hydra.launcher.nodes=2: only 1 of its nodes have 32 CPUs, 200.0 GB; use hydra.launcher.nodes=1"
    )
    assert refusal(_params(), "") is None  # nothing to judge by: submit


def test_the_training_config_reaches_the_check() -> None:
    """slurm.yaml's numbers and the workers a fix can name, as the launcher's setup sees them."""
    from hydra import compose, initialize_config_dir

    from rlgrasp.config import CONFIG_DIR, register_configs
    from rlgrasp.slurm import _workers, refusal

    register_configs()
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(
            "train", overrides=["hydra/launcher=slurm", "experiment=smoke"], return_hydra_config=True
        )
        fixed = compose(
            "train",
            overrides=["hydra/launcher=slurm", "experiment=smoke", "hydra.launcher.cpus_per_task=3"],
            return_hydra_config=True,
        )
    assert (_workers(cfg), _workers(fixed)) == (2, None)
    line = refusal(_launcher_params("experiment=smoke"), SINFO, _workers(cfg))
    assert "use collector.num_workers=1 or hydra.launcher.cpus_per_task=2" in line


# ---------------------------------------------------------------------------------------------
# Waiting for the jobs (scontrol text and a stand-in clock, no cluster)

SCONTROL = """\
JobId=12 ArrayJobId=12 ArrayTaskId=2-3%32 JobName=train JobState=PENDING Reason=Priority Dependency=(null)
JobId=13 ArrayJobId=12 ArrayTaskId=0 JobName=train JobState=RUNNING Reason=None
JobId=14 ArrayJobId=12 ArrayTaskId=1 JobName=train JobState=CANCELLED Reason=None
JobId=20 JobName=train JobState=PENDING Reason=ReqNodeNotAvail,_UnavailableNodes:vm
JobId=30 ArrayJobId=30 ArrayTaskId=4294967294 ArrayTaskThrottle=2 JobName=train JobState=CANCELLED Reason=None
"""


def test_scontrol_records_are_keyed_like_submitit_job_ids() -> None:
    from rlgrasp.slurm import parse_scontrol_jobs

    assert parse_scontrol_jobs(SCONTROL) == {
        "12_2": ("PENDING", "Priority"),
        "12_3": ("PENDING", "Priority"),
        "12_0": ("RUNNING", "None"),
        "12_1": ("CANCELLED", "None"),
        "20": ("PENDING", "ReqNodeNotAvail,_UnavailableNodes:vm"),
        "30": ("CANCELLED", "None"),  # the whole array, cancelled before it started
    }


class _Job:
    """What the watch reads of a submitit job: its id, tasks and result/log paths."""

    def __init__(self, job_id: str, folder: Path) -> None:
        self.job_id, self.num_tasks = job_id, 1
        self.paths = type(
            "Paths",
            (),
            {"result_pickle": folder / f"{job_id}_0_result.pkl", "stderr": folder / f"{job_id}_0_log.err"},
        )()

    def task(self, i: int) -> _Job:
        return self


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _watch(tmp_path: Path, answers: dict, ids=("5_0", "5_1"), results_at: float | None = None):
    """A Watch over jobs ``ids`` whose scontrol answers ``answers[job id]`` (a callable of the time or a
    fixed (state, reason)), polled every second of a stand-in clock until it ends; every job's result
    file appears at ``results_at``. Returns (ended at, the JobLost or None, the jobs)."""
    from rlgrasp.slurm import JobLost, Watch

    clock, jobs = _Clock(), [_Job(i, tmp_path) for i in ids]

    def query(left: list[str]):  # scontrol is asked about whole arrays
        arrays = {j.split("_")[0] for j in left}
        states = {
            j: (a(clock.now) if callable(a) else a) for j, a in answers.items() if j.split("_")[0] in arrays
        }
        return {j: state for j, state in states.items() if state is not None}

    watch = Watch(jobs, query=query, clock=clock)
    try:
        while True:
            if results_at is not None and clock.now >= results_at:
                for job in jobs:
                    job.paths.result_pickle.touch()
            if watch.check():
                break
            clock.now += 1
            if clock.now > 3600:
                raise AssertionError("still waiting after an hour")
    except JobLost as lost:
        return clock.now, lost, jobs
    return clock.now, None, jobs


def test_a_cancelled_job_ends_the_wait_naming_it_and_its_state(tmp_path: Path) -> None:
    from rlgrasp.slurm import GRACE_S

    (tmp_path / "5_0_0_log.err").write_text("starting\nslurmstepd: error: *** JOB 5 CANCELLED ***\n")
    answers = {
        "5_0": lambda t: ("RUNNING", "None") if t < 30 else ("CANCELLED", "None"),
        "5_1": ("RUNNING", "None"),
    }
    ended_at, lost, _ = _watch(tmp_path, answers)
    assert 30 + GRACE_S <= ended_at <= 30 + 5 + GRACE_S + 1  # seen at the next query, then the grace
    assert str(lost) == (
        f"SLURM job 5_0 ended with JobState=CANCELLED without writing a result; log "
        f"{tmp_path / '5_0_0_log.err'} ends with: slurmstepd: error: *** JOB 5 CANCELLED "
        "***; 1 other job(s) of this sweep are still queued or running (squeue -j 5)"
    )
    assert lost.cancel == []


def test_an_array_record_without_tasks_stands_for_each_of_them(tmp_path: Path) -> None:
    def meta(t: float):
        return ("PENDING", "None") if t < 10 else ("CANCELLED", "None")

    _, lost, _ = _watch(tmp_path, {"5": meta})
    assert str(lost) == "SLURM job 5_0 ended with JobState=CANCELLED without writing a result; so did 5_1"


def test_a_job_slurm_forgot_ends_the_wait_and_a_late_result_does_not(tmp_path: Path) -> None:
    _, lost, _ = _watch(tmp_path, {"5_0": None, "5_1": ("PENDING", "None")})  # purged: no record
    assert str(lost).startswith("SLURM job 5_0 is no longer known to SLURM (ended) without writing a result")

    def done(t: float):  # COMPLETED; its result shows on the shared file system 10 s later
        return ("RUNNING", "None") if t < 30 else ("COMPLETED", "None")

    ended_at, lost, _ = _watch(tmp_path, {"5_0": done, "5_1": done}, results_at=40)
    assert lost is None and ended_at == 40


def test_a_requeued_job_is_not_lost(tmp_path: Path) -> None:
    """Preempted: ended for a moment, then PENDING again (SLURM requeued it), then its rerun's result."""

    def requeued(t: float):
        return (
            ("PREEMPTED", "None")
            if 20 <= t < 30
            else ("PENDING", "BeginTime")
            if t < 100
            else ("RUNNING", "None")
        )

    ended_at, lost, _ = _watch(tmp_path, {"5_0": requeued}, ids=("5_0",), results_at=200)
    assert lost is None and ended_at == 200


def test_a_job_slurm_can_never_start_ends_the_wait_and_is_cancelled(tmp_path: Path) -> None:
    ended_at, lost, _ = _watch(
        tmp_path, {"5_0": ("PENDING", "PartitionConfig"), "5_1": ("PENDING", "PartitionConfig")}
    )
    assert ended_at == 0  # the first answer says it
    assert str(lost) == (
        "SLURM job 5_0 can never start: pending with Reason=PartitionConfig (it asks for "
        "more than the partition's nodes or limits allow); cancelled 5_0, 5_1"
    )
    assert lost.cancel == ["5_0", "5_1"]


def test_a_job_waiting_for_an_administrator_is_said_at_once_and_given_up_later(
    tmp_path: Path, caplog
) -> None:
    from rlgrasp.slurm import BLOCKED_LIMIT_S

    with caplog.at_level("WARNING", logger="rlgrasp.slurm"):
        ended_at, lost, _ = _watch(
            tmp_path,
            {
                "5_0": ("PENDING", "ReqNodeNotAvail,_UnavailableNodes:vm"),
                "5_1": ("PENDING", "ReqNodeNotAvail,_UnavailableNodes:vm"),
            },
        )
    (warning,) = caplog.messages  # once for the array, when first seen
    assert warning.startswith("SLURM job 5_0 is pending with Reason=ReqNodeNotAvail, UnavailableNodes:vm")
    assert BLOCKED_LIMIT_S <= ended_at <= BLOCKED_LIMIT_S + 60
    assert "has been pending with Reason=ReqNodeNotAvail" in str(lost) and "it stays queued" in str(lost)
    assert lost.cancel == []


def test_no_answer_from_the_controller_is_not_a_verdict(tmp_path: Path) -> None:
    from rlgrasp.slurm import Watch

    clock = _Clock()
    watch = Watch([_Job("5_0", tmp_path)], query=lambda left: None, clock=clock)
    for _ in range(600):
        assert not watch.check()
        clock.now += 1
    (tmp_path / "5_0_0_result.pkl").touch()
    assert watch.check()


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
    out = subprocess.run(
        ["scontrol", "-o", "show", "job", job_id], capture_output=True, text=True, check=True, timeout=30
    ).stdout
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


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_two_seed_multirun_on_slurm(slurm, tmp_path: Path) -> None:
    """Two seeds as a SLURM job array through hydra/launcher=slurm, sized by the config (1 CPU each)."""
    start = time.monotonic()
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "train.py"),
            "-m",
            "hydra/launcher=slurm",
            "experiment=smoke",
            "seed=0,1",
            f"paths.root_dir={tmp_path}",
            "hydra.launcher.timeout_min=10",
            *TINY,
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=_job_env(),
        timeout=600,
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
        [
            sys.executable,
            str(ROOT / "scripts" / "train.py"),
            "-m",
            "hydra/launcher=slurm",
            "experiment=smoke",
            "seed=0",
            f"paths.root_dir={tmp_path}",
            f"total_frames={frames}",
            "checkpoint.interval_frames=1024",
            "eval.interval_frames=4096",
            "hydra.launcher.timeout_min=30",
            "logger=none",
            *IN_PROCESS,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=tmp_path,
        env=_job_env(),
    )
    try:
        sweeps = tmp_path / "outputs" / "multirun" / "smoke"
        job = wait_for(lambda: next(sweeps.glob("*/0/checkpoints/last.pt"), None), timeout=300).parents[1]
        (job_id,) = re.findall(
            r"^\s+id: '?(\d+(?:_\d+)?)'?$", (job / ".hydra" / "hydra.yaml").read_text(), re.M
        )
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


def _default_partition_cpus() -> int:
    """The most CPUs a node of the cluster's default partition has."""
    from rlgrasp.slurm import SINFO_FORMAT, parse_sinfo

    text = subprocess.run(
        ["sinfo", "-h", "-N", "-o", SINFO_FORMAT], capture_output=True, text=True, check=True, timeout=30
    ).stdout
    return max(n.cpus for n in parse_sinfo(text) if n.default)


def _queued(name: str) -> list[str]:
    """Ids of the jobs named ``name`` SLURM still lists."""
    return subprocess.run(
        ["squeue", "-h", "-r", "-n", name, "-o", "%i"], capture_output=True, text=True, check=True, timeout=30
    ).stdout.split()


def _sweep(
    tmp_path: Path, name: str, *overrides: str, env: dict[str, str] | None = None, seeds: str = "0,1"
) -> subprocess.Popen:
    """A smoke multirun over ``seeds`` through hydra/launcher=slurm, its jobs named ``name``."""
    return subprocess.Popen(
        [
            sys.executable,
            str(ROOT / "scripts" / "train.py"),
            "-m",
            "hydra/launcher=slurm",
            "experiment=smoke",
            f"seed={seeds}",
            f"paths.root_dir={tmp_path}",
            f"hydra.launcher.name={name}",
            "logger=none",
            *overrides,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=env or _job_env(),
    )


def _finish(proc: subprocess.Popen, timeout: float) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        raise AssertionError(
            f"the launcher still waits after {timeout} s:\n{out[-2000:]}{err[-2000:]}"
        ) from None


def test_a_job_no_node_can_run_is_refused_before_submitting(slurm, tmp_path: Path) -> None:
    """One CPU more than the biggest node: refused in one line, exit code 2, nothing submitted, no
    sweep directory."""
    cpus = _default_partition_cpus()
    name = f"rlgrasp-refused-{os.getpid()}"
    before = subprocess.run(["squeue", "-h", "-o", "%i"], capture_output=True, text=True, timeout=30).stdout
    out, err = _finish(_sweep(tmp_path, name, f"collector.num_workers={cpus}"), timeout=120)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err[-3000:]
    assert lines[0].startswith("error: SLURM partition ") and "Traceback" not in out + err
    assert f"hydra.launcher.cpus_per_task={cpus + 1} (collector.num_workers={cpus} + 1" in lines[0]
    assert (
        f"its nodes have at most {cpus}; use collector.num_workers={cpus - 1} or "
        f"hydra.launcher.cpus_per_task={cpus}" in lines[0]
    )
    assert _queued(name) == []
    after = subprocess.run(["squeue", "-h", "-o", "%i"], capture_output=True, text=True, timeout=30).stdout
    assert set(after.split()) <= set(before.split())  # nothing new in the queue
    assert not (tmp_path / "outputs").exists()


def _wait_queued(name: str, proc: subprocess.Popen, state: str, timeout: float = 120) -> list[str]:
    """The ids of jobs ``name`` once SLURM lists them all in ``state``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        out = subprocess.run(
            ["squeue", "-h", "-r", "-n", name, "-o", "%i %T"], capture_output=True, text=True, timeout=30
        ).stdout.split()
        if out and out[1::2] == [state] * (len(out) // 2):
            return out[0::2]
        time.sleep(0.5)
    raise AssertionError(f"jobs {name} not all {state} after {timeout} s")


def test_a_cancelled_job_ends_the_wait_with_its_id_and_state(slurm, tmp_path: Path) -> None:
    """scancel the sweep's jobs while they pend (held an hour by --begin): without accounting
    submitit would poll sacct for ever; the launcher ends within a bounded time, naming a job."""
    name = f"rlgrasp-cancelled-{os.getpid()}"
    proc = _sweep(tmp_path, name, *IN_PROCESS, "+hydra.launcher.additional_parameters.begin=now+3600")
    try:
        ids = _wait_queued(name, proc, "PENDING")
        subprocess.run(["scancel", "-n", name], check=True, timeout=30)
        cancelled = time.monotonic()
        out, err = _finish(proc, timeout=90)
    finally:
        proc.kill()
        subprocess.run(["scancel", "-n", name], timeout=30)
    assert proc.returncode == 1, out[-2000:] + err[-3000:]
    (first, second) = sorted(ids)
    assert err.strip().splitlines()[-1] == (
        f"error: SLURM job {first} ended with JobState=CANCELLED without writing a result; so did {second}"
    ), err[-3000:]
    assert "Traceback" not in err and "Bypassing sacct error" not in out + err
    print(f"pending jobs cancelled: the launcher ended {time.monotonic() - cancelled:.1f} s later")


@pytest.mark.slow
def test_a_job_killed_while_it_runs_ends_the_wait_with_its_log(slurm, tmp_path: Path) -> None:
    """SIGKILL to the job's training process (what the OOM killer does): the job FAILED without a
    result and the launcher says so, with the end of the job's log. (A plain scancel of a running
    job is taken by training as a preemption: the job requeues itself and is waited for.)"""
    name = f"rlgrasp-killed-{os.getpid()}"
    proc = _sweep(
        tmp_path, name, *IN_PROCESS, "total_frames=10000000", "hydra.launcher.timeout_min=30", seeds="0"
    )
    try:
        (job_id,) = _wait_queued(name, proc, "RUNNING")
        task = wait_for(
            lambda: (
                subprocess.run(
                    ["pgrep", "-f", f"submitit.core._submit {tmp_path}"], capture_output=True, text=True
                ).stdout.split()
                or None
            ),
            120,
        )
        os.kill(int(task[0]), signal.SIGKILL)
        killed = time.monotonic()
        out, err = _finish(proc, timeout=120)
    finally:
        proc.kill()
        subprocess.run(["scancel", "-n", name], timeout=30)
    assert proc.returncode == 1, out[-2000:] + err[-3000:]
    last = err.strip().splitlines()[-1]
    assert last.startswith(
        f"error: SLURM job {job_id} ended with JobState=FAILED without writing a result; log {tmp_path}"
    ), err[-3000:]
    assert "ends with: " in last and "Traceback" not in err
    print(f"running job killed: the launcher ended {time.monotonic() - killed:.1f} s later")


def test_a_too_big_job_submitted_unchecked_is_cancelled_by_the_launcher(slurm, tmp_path: Path) -> None:
    """Without sinfo the request is not checked before submitting (a stand-in sinfo that fails): the
    too big job pends with Reason=PartitionConfig, and the launcher cancels it and says so."""
    cpus = _default_partition_cpus()
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "sinfo").write_text("#!/bin/sh\necho 'sinfo: error: stand-in' >&2\nexit 1\n")
    (bin_dir / "sinfo").chmod(0o755)
    env = {**_job_env(), "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}
    name = f"rlgrasp-never-{os.getpid()}"
    proc = _sweep(tmp_path, name, f"collector.num_workers={cpus}", env=env)
    try:
        out, err = _finish(proc, timeout=120)
    finally:
        proc.kill()
        subprocess.run(["scancel", "-n", name], timeout=30)
    assert proc.returncode == 1, out[-2000:] + err[-3000:]
    last = err.strip().splitlines()[-1]
    assert re.fullmatch(
        r"error: SLURM job \d+_[01] can never start: pending with Reason=PartitionConfig "
        r"\(.*\); cancelled \d+_[01], \d+_[01]",
        last,
    ), err[-3000:]
    assert wait_for(lambda: True if not _queued(name) else None, timeout=30)
