"""``hydra/launcher=slurm``: hydra-submitit-launcher's SlurmLauncher that never waits silently.

Two gaps of the plugin (through submitit) make a sweep wait for ever without a word:

- A job that asks for more than any node of its partition has (CPUs, memory, GPUs, nodes, time)
  stays PENDING for ever (``Reason=PartitionConfig``). Before anything is submitted, the request is
  compared with what ``sinfo`` reports, and such a job is refused in one line naming the key and
  how to fix it (``refusal``). Without ``sinfo`` nothing is said and the jobs are submitted.
- submitit learns a job's state from ``sacct``, which fails on a cluster without accounting, so a
  cancelled or failed job that left no result is polled for ever. The launcher waits on its own
  loop instead (``Watch``): result files every second, ``scontrol show job`` (which works without
  accounting) every 5-30 s; a job that ended without a result, or that SLURM can never start, ends
  the wait with one line naming the job and its state.

Hydra takes launchers only from the ``hydra_plugins`` package: ``hydra_plugins.rlgrasp_slurm`` names
this launcher there. Jobs receive the plugin's own SlurmLauncher (``__reduce_ex__``).
"""

from __future__ import annotations

import copyreg
import logging
import math
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hydra.core.singleton import Singleton
from hydra.core.utils import JobReturn, filter_overrides
from hydra.types import HydraContext, TaskFunction
from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf
from hydra_plugins.hydra_submitit_launcher.submitit_launcher import SlurmLauncher
from omegaconf import DictConfig, OmegaConf

log = logging.getLogger(__name__)

#: One line per node and partition: name, CPUs, RealMemory (MB), partition (``*``: the default),
#: the partition's time limit, generic resources (GPUs).
SINFO_FORMAT = "%N|%c|%m|%P|%l|%G"
KEY = "hydra.launcher."


# --- what the cluster offers ------------------------------------------------------------------
@dataclass(frozen=True)
class Node:
    """One node of one partition, as ``sinfo -N`` lists it (a node in two partitions is two rows)."""

    name: str
    partition: str
    default: bool  # the cluster's default partition
    cpus: int
    mem_mb: int
    gpus: int
    max_time_min: float | None  # the partition's MaxTime; None: no limit


def parse_sinfo(text: str) -> list[Node]:
    """The nodes in ``sinfo -h -N -o SINFO_FORMAT`` output (lines it cannot read are skipped)."""
    nodes = []
    for line in text.splitlines():
        parts = line.strip().split("|")
        if len(parts) != 6:
            continue
        name, cpus, mem, partition, limit, gres = parts
        try:
            nodes.append(
                Node(
                    name,
                    partition.rstrip("*"),
                    partition.endswith("*"),
                    int(cpus.rstrip("+")),
                    int(mem.rstrip("+")),
                    _gres_gpus(gres),
                    slurm_minutes(limit),
                )
            )
        except ValueError:
            continue
    return nodes


def slurm_minutes(text: str) -> float | None:
    """A SLURM time (``infinite``, ``30``, ``30:00``, ``2:00:00``, ``1-12``, ``1-00:00:00``) in minutes;
    None for no limit."""
    text = text.strip()
    if text.lower() in ("infinite", "unlimited", "n/a", "none", ""):
        return None
    days, _, clock = text.rpartition("-")
    fields = [float(f) for f in clock.split(":")]
    if days:  # days-hours[:minutes[:seconds]]
        h, m, s = (fields + [0.0, 0.0])[:3]
        return float(days) * 1440 + h * 60 + m + s / 60
    if len(fields) == 3:  # hours:minutes:seconds
        return fields[0] * 60 + fields[1] + fields[2] / 60
    return fields[0] + (fields[1] / 60 if len(fields) == 2 else 0.0)  # minutes[:seconds]


def _gres_gpus(gres: str) -> int:
    """GPUs in a gres string such as ``gpu:2``, ``gpu:a100:4(S:0-1)``, ``gpu:1,mps:100``, ``(null)``."""
    gpus = 0
    for item in re.sub(r"\([^)]*\)", "", gres).split(","):
        kind, _, rest = item.partition(":")
        if kind == "gpu":
            count = rest.rpartition(":")[2]
            gpus += int(count) if count.isdigit() else 1
    return gpus


def sinfo_text() -> str | None:
    """What ``sinfo`` says about every node, or None when it cannot say (no SLURM commands here, or
    no controller answers: sbatch will then report it)."""
    if shutil.which("sinfo") is None:
        return None
    try:
        # --all: hidden partitions too (a job may name one), or the check would call them unknown
        proc = subprocess.run(
            ["sinfo", "--all", "-h", "-N", "-o", SINFO_FORMAT], capture_output=True, text=True, timeout=30
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return proc.stdout if proc.returncode == 0 else None


# --- what the job asks for --------------------------------------------------------------------
def _mb(value: Any) -> float:
    """A SLURM memory size (``2G``, ``2048M``, ``2048``: MB, ``1T``) in MB."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([KMGT]?)B?\s*", str(value), re.I)
    if match is None:
        raise ValueError(f"not a memory size: {value!r}")
    return float(match[1]) * {"K": 1 / 1024, "": 1, "M": 1, "G": 1024, "T": 1024**2}[match[2].upper()]


def _count(value: Any) -> int:
    """A GPU count as the launcher keys take it: ``2``, ``"a100:2"``, ``"gpu:a100:2"``."""
    return 0 if value is None else int(str(value).rpartition(":")[2])


@dataclass(frozen=True)
class Request:
    """One job's request per node, from the launcher's parameters (hydra-submitit-launcher keys)."""

    partitions: tuple[str, ...]  # empty: the default partition
    cpus_per_task: int
    tasks: int  # per node
    mem_mb: float | None  # per node; None: the cluster's default
    mem_key: str  # the key(s) that set the memory, as the user would type them
    gpus: int  # per node
    gpu_key: str
    nodes: int
    timeout_min: float

    @property
    def cpus(self) -> int:
        return self.cpus_per_task * self.tasks

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Request:
        tasks, cpt = int(params.get("tasks_per_node") or 1), int(params.get("cpus_per_task") or 1)
        mem_mb, mem_key = None, ""
        if params.get("mem_gb") is not None:
            mem_mb, mem_key = float(params["mem_gb"]) * 1024, f"{KEY}mem_gb={params['mem_gb']}"
        elif params.get("mem_per_cpu") is not None:
            mem_mb = _mb(params["mem_per_cpu"]) * cpt * tasks
            mem_key = f"{KEY}mem_per_cpu={params['mem_per_cpu']}"
        asked = {
            "gpus_per_node": _count(params.get("gpus_per_node")),
            "gpus_per_task": _count(params.get("gpus_per_task")) * tasks,
            "gres": _gres_gpus(str(params.get("gres") or "")),
        }
        gpu_key = max(asked, key=asked.__getitem__)
        partition = params.get("partition")
        return cls(
            tuple(p for p in str(partition or "").split(",") if p),
            cpt,
            tasks,
            mem_mb,
            mem_key,
            asked[gpu_key],
            f"{KEY}{gpu_key}={params.get(gpu_key)}",
            int(params.get("nodes") or 1),
            float(params.get("timeout_min") or 0),
        )


# --- can it ever run? -------------------------------------------------------------------------
def refusal(params: Mapping[str, Any], sinfo: str, workers: int | None = None) -> str | None:
    """The one line refusing a job that no node of its partition can ever run, or None (also when
    ``sinfo`` lists nothing to judge by). ``workers``: ``collector.num_workers`` when ``cpus_per_task``
    is derived from it (then the fix names it)."""
    nodes = parse_sinfo(sinfo)
    if not nodes:
        return None
    request = Request.from_params(params)
    names = list(dict.fromkeys(n.partition for n in nodes))
    wanted = list(request.partitions) or [n.partition for n in nodes if n.default][:1]
    if not wanted:
        return (
            f"error: {KEY}partition=null but the SLURM cluster has no default partition; "
            f"set {KEY}partition to one of {', '.join(names)}"
        )
    unknown = [p for p in wanted if p not in names]
    if unknown:
        return (
            f"error: {KEY}partition={','.join(request.partitions)}: no SLURM partition {unknown[0]}; "
            f"sinfo lists {', '.join(names)}"
        )
    verdicts = {p: _problems(request, [n for n in nodes if n.partition == p], workers) for p in wanted}
    if any(not problems for problems in verdicts.values()):
        return None
    partition, problems = next(iter(verdicts.items()))
    more = f" (and {len(problems) - 1} more: {'; '.join(problems[1:])})" if len(problems) > 1 else ""
    return f"error: SLURM partition {partition} can never run this job: {problems[0]}{more}"


def _problems(request: Request, nodes: Sequence[Node], workers: int | None) -> list[str]:
    """Each reason ``nodes`` (one partition) can never run ``request``, as ``key=value: why; fix``."""
    most = Node(
        "",
        nodes[0].partition,
        False,
        max(n.cpus for n in nodes),
        max(n.mem_mb for n in nodes),
        max(n.gpus for n in nodes),
        None,
    )
    limits = [n.max_time_min for n in nodes]
    max_time = None if None in limits else max(t for t in limits if t is not None)
    problems = [
        p
        for p in (
            _cpu_problem(request, most, workers),
            _mem_problem(request, most),
            _gpu_problem(request, most),
        )
        if p
    ]
    if max_time is not None and request.timeout_min > max_time:
        problems.append(
            f"{KEY}timeout_min={request.timeout_min:g}: its time limit is {max_time:g} min; "
            f"use {KEY}timeout_min={math.floor(max_time)}"
        )
    if not problems:
        problems += _node_problems(request, nodes)
    return problems


def _cpu_problem(request: Request, most: Node, workers: int | None) -> str | None:
    if request.cpus <= most.cpus:
        return None
    per_task = most.cpus // request.tasks
    fixes = [f"{KEY}cpus_per_task={per_task}"] if per_task else [f"{KEY}tasks_per_node={most.cpus}"]
    if workers is not None and request.tasks == 1:
        fixes.insert(0, f"collector.num_workers={most.cpus - 1}")
    asked = f"{KEY}cpus_per_task={request.cpus_per_task}"
    if workers is not None:
        asked += f" (collector.num_workers={workers} + 1 for the learner)"
    if request.tasks > 1:
        asked += f" x {KEY}tasks_per_node={request.tasks}"
    return f"{asked} asks for {request.cpus} CPUs per node, its nodes have at most {most.cpus}; use " + (
        " or ".join(fixes)
    )


def _mem_problem(request: Request, most: Node) -> str | None:
    # Per-CPU memory is judged for the CPUs a node can give: the CPU fix, if any, lowers it too.
    cpus = min(request.cpus, most.cpus)
    need = None if request.mem_mb is None else request.mem_mb * cpus / request.cpus
    if need is None or need <= most.mem_mb:
        return None
    per_cpu_fix = f"{KEY}mem_per_cpu={most.mem_mb // cpus}M"
    if "mem_per_cpu" in request.mem_key:
        fix = per_cpu_fix
    elif most.mem_mb >= 1024:
        fix = f"{KEY}mem_gb={most.mem_mb // 1024}"
    else:  # mem_gb takes whole GB only
        fix = f"{KEY}mem_gb=null {per_cpu_fix}"
    per_cpu = f" x {cpus} CPUs" if "mem_per_cpu" in request.mem_key else ""
    return (
        f"{request.mem_key}{per_cpu} asks for {need / 1024:.1f} GB per node, its nodes have at most "
        f"{most.mem_mb / 1024:.1f} GB ({most.mem_mb} MB); use {fix}"
    )


def _gpu_problem(request: Request, most: Node) -> str | None:
    if request.gpus <= most.gpus:
        return None
    offer = f"at most {most.gpus}" if most.gpus else "none"
    fix = f"{KEY}gpus_per_node={most.gpus}" if most.gpus else f"a partition with GPUs ({KEY}partition=<name>)"
    return f"{request.gpu_key} asks for {request.gpus} GPU(s) per node, its nodes have {offer}; use {fix}"


def _node_problems(request: Request, nodes: Sequence[Node]) -> list[str]:
    """Enough nodes for each resource alone, but not for all of them at once (a mixed partition)."""
    fit = [
        n
        for n in nodes
        if n.cpus >= request.cpus
        and n.gpus >= request.gpus
        and (request.mem_mb is None or n.mem_mb >= request.mem_mb)
    ]
    if len(fit) >= request.nodes:
        return []
    want = (
        f"{request.cpus} CPUs"
        + (f", {request.mem_mb / 1024:.1f} GB" if request.mem_mb else "")
        + (f", {request.gpus} GPUs" if request.gpus else "")
    )
    if not fit:
        return [
            f"{KEY}cpus_per_task={request.cpus_per_task} with {request.mem_key or 'its memory'}: "
            f"no single node has {want} at once; lower one of them"
        ]
    return [
        f"{KEY}nodes={request.nodes}: only {len(fit)} of its nodes have {want}; use {KEY}nodes={len(fit)}"
    ]


# --- waiting for the jobs ---------------------------------------------------------------------
#: States of a job that may still write its result (a requeued job is PENDING again).
ALIVE = {
    "PENDING",
    "RUNNING",
    "CONFIGURING",
    "COMPLETING",
    "REQUEUED",
    "REQUEUE_HOLD",
    "REQUEUE_FED",
    "RESIZING",
    "SUSPENDED",
    "STOPPED",
    "SIGNALING",
    "STAGE_OUT",
    "SPECIAL_EXIT",
    "RESV_DEL_HOLD",
}
#: Pending reasons no waiting cures: the job is cancelled and the wait ends at once.
NEVER = {
    "PartitionConfig": "it asks for more than the partition's nodes or limits allow",
    "PartitionNodeLimit": "it asks for more nodes than the partition allows",
    "PartitionTimeLimit": "its time limit exceeds the partition's MaxTime",
    "BadConstraints": "no node satisfies its constraints",
    "DependencyNeverSatisfied": "a job it depends on failed",
    "InvalidAccount": "its account is invalid",
    "InvalidQOS": "its QOS is invalid",
    "AccountNotAllowed": "its account may not use the partition",
}
#: Pending reasons only an administrator cures (nodes down, drained, reserved for maintenance): said
#: at once, and the wait ends after BLOCKED_LIMIT_S; the job stays queued.
BLOCKED = {
    "ReqNodeNotAvail": "nodes it needs are down, drained or reserved",
    "NodeDown": "a node it needs is down",
    "PartitionDown": "the partition is down",
    "PartitionInactive": "the partition is inactive",
    "JobHeldAdmin": "an administrator holds it",
}
BLOCKED_LIMIT_S = 600.0
#: How long a job that ended may take to show its result (submitit's own allowance for a slow
#: shared file system), and how often scontrol is asked at least and at most.
GRACE_S = 15.0
QUERY_EVERY_S = (5.0, 30.0)

States = dict[str, tuple[str, str]]  # job id -> (JobState, Reason)


class JobLost(RuntimeError):
    """A job will never write its result; the message is one line. ``cancel``: job ids to scancel."""

    def __init__(self, message: str, cancel: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.cancel = list(cancel)


def parse_scontrol_jobs(text: str) -> States:
    """``scontrol -o show job`` output as {job id: (JobState, Reason)}; array tasks as ``<array>_<task>``
    (the ids submitit uses), a not yet started range of tasks expanded. A record of a whole array
    without its tasks (``ArrayTaskId=4294967294``, e.g. once cancelled before it started) stays
    under the array's id: ``Watch`` falls back to it."""
    states: States = {}
    for line in text.splitlines():
        fields: dict[str, str] = {}
        for key, value in re.findall(r"(\w+)=(\S*)", line):
            fields.setdefault(key, value)
        if "JobId" not in fields or "JobState" not in fields:
            continue
        state = (fields["JobState"], fields.get("Reason", "None"))
        array, tasks = fields.get("ArrayJobId"), fields.get("ArrayTaskId", "")
        if array and re.fullmatch(r"[\d,:-]+(%\d+)?", tasks) and tasks != "4294967294":  # SLURM's NO_VAL
            states.update({f"{array}_{t}": state for t in _expand(tasks.split("%")[0])})
        else:
            states[fields["JobId"]] = state
    return states


def _expand(tasks: str) -> list[int]:
    """``0-3,7,10-20:5`` as a list of task ids."""
    ids = []
    for part in tasks.split(","):
        span, _, step = part.partition(":")
        low, _, high = span.partition("-")
        ids.extend(range(int(low), int(high or low) + 1, int(step or 1)))
    return ids


def scontrol_states(job_ids: Iterable[str]) -> States | None:
    """The jobs' states (a job SLURM no longer knows is absent), or None when the controller did not
    answer (try again later)."""
    states: States = {}
    for main in sorted({j.split("_")[0] for j in job_ids}):
        try:
            proc = subprocess.run(
                ["scontrol", "-o", "show", "job", main], capture_output=True, text=True, timeout=30
            )
        except (OSError, subprocess.TimeoutExpired):
            return None
        if proc.returncode != 0:
            if "Invalid job id" in proc.stderr:  # ended more than MinJobAge ago
                continue
            return None
        states.update(parse_scontrol_jobs(proc.stdout))
    return states


class Watch:
    """Polls a sweep's jobs until each has its result; ``check`` raises JobLost for a job that never will."""

    def __init__(
        self,
        jobs: Sequence[Any],
        query: Callable[[list[str]], States | None] = scontrol_states,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.jobs, self.query, self.clock = list(jobs), query, clock
        self.start = self.next_query = clock()
        self.ended: dict[str, float] = {}  # job id -> when first seen ended without a result
        self.blocked: dict[str, float] = {}  # job id -> since when pending for a BLOCKED reason
        self.warned: set[str] = set()  # BLOCKED reasons already said (once for a whole array)

    def check(self) -> bool:
        """True once every job has written its result (submitit's result file)."""
        left = [j for j in self.jobs if not _has_result(j)]
        if not left:
            return True
        now = self.clock()
        overdue = any(now - self.ended.get(j.job_id, now) >= GRACE_S for j in left)
        if now < self.next_query and not overdue:
            return False
        low, high = QUERY_EVERY_S
        self.next_query = now + min(high, max(low, (now - self.start) / 10))
        answer = self.query([j.job_id for j in left])
        if answer is not None:
            found = {j.job_id: answer.get(j.job_id) or answer.get(j.job_id.split("_")[0]) for j in left}
            states = {job_id: state for job_id, state in found.items() if state}
            self._judge(left, states, now)
        return False

    def _judge(self, left: list[Any], states: States, now: float) -> None:
        alive = [j for j in left if states.get(j.job_id, ("", ""))[0] in ALIVE]
        for job in left:
            if job in alive:
                self.ended.pop(job.job_id, None)
            else:
                self.ended.setdefault(job.job_id, now)
        lost = [j for j in left if j.job_id in self.ended and now - self.ended[j.job_id] >= GRACE_S]
        if lost:
            state = states.get(lost[0].job_id)
            what = f"ended with JobState={state[0]}" if state else "is no longer known to SLURM (ended)"
            more = f"; so did {_ids(lost[1:])}" if len(lost) > 1 else ""
            running = (
                (
                    f"; {len(alive)} other job(s) of this sweep are still queued or running "
                    f"(squeue -j {alive[0].job_id.split('_')[0]})"
                )
                if alive
                else ""
            )
            raise JobLost(
                f"SLURM job {lost[0].job_id} {what} without writing a result{_log_tail(lost[0])}"
                f"{more}{running}"
            )
        never = [j for j in alive if _reason(states[j.job_id]) in NEVER]
        if never:
            reason = states[never[0].job_id][1]
            raise JobLost(
                f"SLURM job {never[0].job_id} can never start: pending with Reason={reason} "
                f"({NEVER[_reason(states[never[0].job_id])]}); cancelled {_ids(never)}",
                cancel=[j.job_id for j in never],
            )
        for job in alive:
            self._blocked(job.job_id, states[job.job_id], now)

    def _blocked(self, jid: str, state: tuple[str, str], now: float) -> None:
        """Say at once that a job waits for an administrator; stop waiting after BLOCKED_LIMIT_S."""
        if _reason(state) not in BLOCKED:
            self.blocked.pop(jid, None)
            return
        reason = state[1].replace("_", " ")
        self.blocked.setdefault(jid, now)
        if _reason(state) not in self.warned:
            self.warned.add(_reason(state))
            log.warning(
                "SLURM job %s is pending with Reason=%s (%s); waiting at most %d min for it to start",
                jid,
                reason,
                BLOCKED[_reason(state)],
                BLOCKED_LIMIT_S // 60,
            )
        if now - self.blocked[jid] >= BLOCKED_LIMIT_S:
            raise JobLost(
                f"SLURM job {jid} has been pending with Reason={reason} for "
                f"{BLOCKED_LIMIT_S / 60:g} min; stopped waiting (it stays queued: "
                f"scancel {jid.split('_')[0]} to drop it)"
            )


def _reason(state: tuple[str, str]) -> str:
    """The reason's name: ``ReqNodeNotAvail,_UnavailableNodes:n1`` -> ``ReqNodeNotAvail``."""
    return state[1].split(",")[0]


def _ids(jobs: Sequence[Any]) -> str:
    ids = [j.job_id for j in jobs]
    return ", ".join(ids[:3]) + (f" and {len(ids) - 3} more" if len(ids) > 3 else "")


def _has_result(job: Any) -> bool:
    return all(job.task(i).paths.result_pickle.exists() for i in range(job.num_tasks))


def _log_tail(job: Any) -> str:
    """Where the job's log is and its last line (the job's own error, when it printed one)."""
    try:
        path = Path(job.paths.stderr)
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except (OSError, AttributeError):
        return ""
    return f"; log {path}" + (f" ends with: {lines[-1][:200]}" if lines else "")


# --- the launcher -----------------------------------------------------------------------------
class CheckedSlurmLauncher(SlurmLauncher):
    """The plugin's SlurmLauncher (``_target_`` of ``configs/hydra/launcher/slurm.yaml``), refusing a
    job no node can run before anything is submitted, and waiting on its own loop."""

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        # Here, not in launch: the sweeper creates the sweep directory between the two.
        super().setup(hydra_context=hydra_context, task_function=task_function, config=config)
        text = sinfo_text()
        problem = refusal(self.params, text, _workers(config)) if text else None
        if problem:
            print(problem, file=sys.stderr)
            sys.exit(2)

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        jobs = self._submit(job_overrides, initial_job_idx)
        if shutil.which("scontrol") is not None:
            watch = Watch(jobs)
            try:
                while not watch.check():
                    time.sleep(1)
            except JobLost as lost:
                if lost.cancel:
                    subprocess.run(["scancel", *lost.cancel], capture_output=True, timeout=60, check=False)
                print(f"error: {lost}", file=sys.stderr)
                sys.exit(1)
        return [j.results()[0] for j in jobs]  # every result file exists: no sacct call

    def __reduce_ex__(self, protocol: Any) -> Any:
        # Jobs get the plugin's own SlurmLauncher: they only run its __call__ and checkpoint (the
        # requeue), and need neither this class nor the hydra_plugins module that names it.
        return copyreg._reconstructor, (SlurmLauncher, object, None), dict(self.__dict__)

    def _submit(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> list[Any]:
        """The plugin's ``launch`` without its wait (it submits and waits through submitit in one
        method): the same executor, parameters, sweep directory and job array."""
        import submitit  # lazy, as in the plugin: Hydra imports launchers when it discovers plugins

        assert self.config is not None
        init_keys = {"submitit_folder", "max_num_timeout"}
        executor = submitit.AutoExecutor(
            cluster=self._EXECUTOR,
            folder=self.params["submitit_folder"],
            **{f"{self._EXECUTOR}_{k}": v for k, v in self.params.items() if k == "max_num_timeout"},
        )
        base = set(OmegaConf.structured(BaseQueueConf).keys())
        executor.update_parameters(
            **{
                k if k in base else f"{self._EXECUTOR}_{k}": v
                for k, v in self.params.items()
                if k not in init_keys
            }
        )
        log.info(f"Submitit '{self._EXECUTOR}' sweep output dir : {self.config.hydra.sweep.dir}")
        sweep_dir = Path(str(self.config.hydra.sweep.dir))
        sweep_dir.mkdir(parents=True, exist_ok=True)
        if "mode" in self.config.hydra.sweep:
            sweep_dir.chmod(int(str(self.config.hydra.sweep.mode), 8))
        job_params = []
        for idx, overrides in enumerate(job_overrides, start=initial_job_idx):
            log.info(f"\t#{idx} : {' '.join(filter_overrides(overrides))}")
            job_params.append(
                (list(overrides), "hydra.sweep.dir", idx, f"job_id_for_{idx}", Singleton.get_state())
            )
        return executor.map_array(self, *zip(*job_params))


def _workers(config: DictConfig) -> int | None:
    """``collector.num_workers`` when ``cpus_per_task`` is the config's workers + 1 (not a number given)."""
    raw = OmegaConf.to_container(config.hydra.launcher, resolve=False).get("cpus_per_task")
    workers = OmegaConf.select(config, "collector.num_workers")
    derived = isinstance(raw, str) and "collector.num_workers" in raw
    return int(workers) if derived and workers is not None else None
