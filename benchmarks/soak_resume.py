"""Kill -9 soak of resume: N cycles of start-or-resume, a random wait, ``kill -9`` of the whole process
group (learner and collector workers); then every check, and a final resume that runs to the end.

    python benchmarks/soak_resume.py --cycles 3 [--out /tmp/soak] [--seed 0] [--wait 15 40] [--total-frames N]

Checks after each kill: the command was still running when killed (a cycle that reaches the end tests
nothing); no process of the group is left; every file under ``checkpoints/`` loads
(``weights_only``); the newest checkpoint's frames never go backwards; what the kill lost (frames the
learner had reached minus the newest checkpoint's) is at most one checkpoint interval. At the end:
the final resume exits 0 at ``total_frames`` and the TensorBoard curves have no duplicated or
backwards steps. Prints one line per cycle and a Markdown table (docs/benchmarks/reliability.md);
exit code 1 if any check failed. ``--record PAGE/ID`` writes the cycles that passed and the most
frames a kill lost into that row of docs/benchmarks/results.json and its page's table
(benchmarks/results_file.py): ``nice -n 19 python benchmarks/soak_resume.py --cycles 10 --record
reliability/soak --record-load shared``.
"""

from __future__ import annotations

import argparse
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_file, also when loaded by path
import results_file

from rlgrasp.policy_file import CheckpointError, newest_readable, read_checkpoint
from rlgrasp.utils import markdown_table
from tests.procs import processes_in_group

ROOT = Path(__file__).resolve().parents[1]
PROGRESS = re.compile(r"frames ([\d,]+)/")


def train_command(out: Path, seed: int, total: int, interval: int) -> list[str]:
    return [
        sys.executable,
        str(ROOT / "scripts" / "train.py"),
        "experiment=smoke",
        "resume=auto",
        f"seed={seed}",
        f"paths.root_dir={out}",
        f"total_frames={total}",
        f"checkpoint.interval_frames={interval}",
        "eval.interval_frames=4096",
    ]


def run_dirs(out: Path, seed: int) -> list[Path]:
    return sorted((out / "outputs" / "train" / "smoke").glob(f"*_s{seed}_*"))


def check_checkpoints(run: Path) -> tuple[int, list[str]]:
    """(frames of the newest readable checkpoint, problems): every file must load."""

    problems = []
    for path in sorted((run / "checkpoints").glob("*.pt")):
        try:
            read_checkpoint(path)
        except CheckpointError as exc:
            problems.append(str(exc))
    try:
        return newest_readable(run)[1]["frames"], problems
    except CheckpointError:
        return 0, problems


def reached(log_text: str) -> int:
    """The last frame count the learner logged in this part of train.log (0: none)."""
    found = PROGRESS.findall(log_text)
    return int(found[-1].replace(",", "")) if found else 0


def kill_cycle(cmd: list[str], wait_s: float, log_file: Path) -> tuple[int, float, list[int], int | None]:
    """Start the command in its own process group, wait, kill -9 the group: (pgid, waited, left, exit
    code if the command ended by itself before the kill, else None)."""
    with open(log_file, "a") as out:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    t0 = time.monotonic()
    ended = None
    try:
        ended = proc.wait(timeout=wait_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    waited = time.monotonic() - t0
    deadline = time.monotonic() + 10
    while processes_in_group(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    return proc.pid, waited, processes_in_group(proc.pid), ended


def tensorboard_problems(run: Path) -> list[str]:
    acc = EventAccumulator(str(run / "tensorboard"), size_guidance={"scalars": 0})
    acc.Reload()
    problems = []
    for tag in acc.Tags()["scalars"]:
        steps = [e.step for e in acc.Scalars(tag)]
        bad = [(a, b) for a, b in zip(steps, steps[1:]) if b <= a]
        if bad:
            problems.append(f"{tag}: steps not increasing at {bad[:3]}")
    return problems


def soak(args: argparse.Namespace) -> int:
    rng = random.Random(args.seed)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    cmd = train_command(out, args.seed, args.total_frames, args.interval)
    rows, failures, best = [], [], 0
    for cycle in range(1, args.cycles + 1):
        runs = run_dirs(out, args.seed)
        log_start = {r: (r / "train.log").stat().st_size for r in runs if (r / "train.log").exists()}
        pgid, waited, left, ended = kill_cycle(cmd, rng.uniform(*args.wait), out / "soak_train_output.txt")
        run = max(run_dirs(out, args.seed), key=lambda r: check_checkpoints(r)[0])
        text = (run / "train.log").read_text()[log_start.get(run, 0) :]
        at_kill = reached(text)
        frames, problems = check_checkpoints(run)
        lost = max(at_kill - frames, 0)
        if left:
            problems.append(f"processes left in group {pgid}: {left}")
        if ended is not None:  # nothing was killed: this cycle tested nothing
            problems.append(f"ended by itself (exit {ended}) before the kill: raise --total-frames")
        if frames < best:
            problems.append(f"frames went backwards: {best} -> {frames}")
        if lost > args.interval:
            problems.append(f"lost {lost} frames, more than one interval ({args.interval})")
        best = max(best, frames)
        verdict = "ok" if not problems else "; ".join(problems)
        rows.append((cycle, f"{waited:.1f}", at_kill, frames, lost, verdict))
        print(
            f"cycle {cycle}: killed after {waited:.1f} s at {at_kill} frames; newest checkpoint "
            f"{frames}; lost {lost}; {rows[-1][-1]}",
            flush=True,
        )
        failures += problems
    return finish(cmd, out, args, rows, failures)


def finish(cmd: list[str], out: Path, args: argparse.Namespace, rows: list, failures: list[str]) -> int:
    t0 = time.monotonic()
    with open(out / "soak_train_output.txt", "a") as log:
        proc = subprocess.run(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, timeout=1800)
    run = max(run_dirs(out, args.seed), key=lambda r: check_checkpoints(r)[0])
    frames, problems = check_checkpoints(run)
    problems += tensorboard_problems(run)
    if proc.returncode != 0 or frames != args.total_frames:
        problems.append(f"final resume: exit {proc.returncode}, {frames} frames (want {args.total_frames})")
    print(
        f"final resume: exit {proc.returncode} after {time.monotonic() - t0:.1f} s at {frames} frames; "
        f"{'ok' if not problems else '; '.join(problems)}"
    )
    failures += problems
    print(
        markdown_table(
            ["cycle", "killed after (s)", "frames reached", "newest checkpoint", "lost", "checks"], rows
        )
    )
    print(f"run dir {run}; {'PASSED' if not failures else 'FAILED: ' + '; '.join(failures)}")
    if getattr(args, "record", None):
        results_file.record(
            *args.record,
            soak_text(rows),
            "missed (FAILED)" if failures else "met (PASSED)",
            load=args.record_load,
        )
    return 1 if failures else 0


def soak_text(rows: list[tuple]) -> str:
    """The results table's ``measured`` cell from the cycles' rows (cycle, waited, frames reached,
    newest checkpoint, lost, checks): how many passed every check, and the most one kill lost."""
    passed = sum(row[-1] == "ok" for row in rows)
    lost = max((row[4] for row in rows), default=0)
    return f"{passed} of {len(rows)} cycles ok, at most {lost:,} frames lost per kill"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cycles", type=int, default=3)
    p.add_argument("--out", default="outputs/soak")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--wait", type=float, nargs=2, default=(15.0, 40.0), metavar=("MIN_S", "MAX_S"))
    p.add_argument(
        "--total-frames",
        type=int,
        default=None,
        help="default: 16,384 per cycle, so that no cycle reaches the end",
    )
    p.add_argument("--interval", type=int, default=2048, help="checkpoint.interval_frames")
    results_file.add_options(p)
    args = p.parse_args()
    args.total_frames = args.total_frames or 16384 * args.cycles
    return soak(args)


if __name__ == "__main__":
    sys.exit(main())
