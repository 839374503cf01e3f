"""Preemption through submitit, on this machine: ``hydra/launcher=local`` (submitit_local) runs the
job as a task under a submitit controller, as SLURM would under the slurm launcher. SIGUSR2 (what
submitit has SLURM send before preemption or the time limit) makes training save a checkpoint and hand
over to submitit, which requeues the job; the restarted task resumes (``resume=auto``) in the same job
directory and runs to ``total_frames``."""

from __future__ import annotations

import os
import re
import signal
from pathlib import Path

import pytest

from rlgrasp import policy_file
from tests.procs import in_group, wait_for

FRAMES = 4096


@pytest.mark.slow
def test_sigusr2_requeues_the_job_which_resumes_in_its_dir(tmp_path: Path, script) -> None:
    sweep = script(
        "train",
        "-m",
        "hydra/launcher=local",
        "experiment=smoke",
        "seed=0",
        "resume=auto",
        f"paths.root_dir={tmp_path}",
        f"total_frames={FRAMES}",
        "checkpoint.interval_frames=1024",
        "eval.interval_frames=100000",
        "logger=none",
        "collector.num_workers=1",
    )
    runs = tmp_path / "outputs" / "multirun" / "smoke"
    last = wait_for(lambda: next(runs.glob("*/0/checkpoints/last.pt"), None), 300, sweep)
    job = last.parents[1]
    (task,) = in_group(sweep.pid, "submitit.core._submit")  # the job's task; its parent is the controller
    os.kill(task, signal.SIGUSR2)  # the task only: the controller has no handler and would die of it
    assert sweep.wait(timeout=600) == 0, sweep.output()[-3000:]

    state = policy_file.load_checkpoint(job)
    assert state["frames"] == FRAMES and state["generation"] == 1  # resumed once, in the same job dir
    log = (job / "train.log").read_text()
    stopped = int(re.search(r"SIGUSR2 at ([\d,]+) frames: saving a checkpoint", log)[1].replace(",", ""))
    assert 1024 <= stopped < FRAMES
    before, after = log.split("handing over to submitit to requeue the job")
    resumed = re.search(r"resuming from (\S+) \(([\d,]+) frames\)", after)
    assert Path(resumed[1]).parents[1] == job and resumed[2] == f"{stopped:,}"  # from the signal's checkpoint
    assert "finished at 4,096 frames" in log
    (submitit_log,) = job.parent.glob(".submitit/*/*_0_log.err")  # submitit logs warnings only
    assert "Caught signal SIGUSR2 on" in submitit_log.read_text()
    assert "this job is preempted" in submitit_log.read_text()
    # the requeued start recorded its own Hydra config next to the launch's
    assert {p.name for p in (job / ".hydra").iterdir()} == {
        "config.yaml",
        "hydra.yaml",
        "overrides.yaml",
        "resume_1",
    }
    assert len(list(runs.iterdir())) == 1 and [p.name for p in runs.glob("*/[0-9]*")] == ["0"]
    assert sweep.left() == []  # neither the controller nor a task nor a collector worker
