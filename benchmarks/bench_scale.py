"""Frames/s of the collector backends side by side: process vs Ray (local, and a two-node Ray
cluster on loopback). Same env, MLP actor, batch layout (grasp_ppo: 2 workers x 8 envs x 64 steps).

    python benchmarks/bench_scale.py [--batches 8] [--warmup 2] [--setups process ray ray_2nodes]
    python benchmarks/bench_scale.py --workers 1 2 4 8 [--setups process] [--plot docs/img/workers.png]

Prints one markdown row per setup (and worker count, with ``--workers``): median and IQR of
frames/s over the timed batches (each batch also pays the weight broadcast that training does after
every update), and with ``--workers`` the ratio to the first count's rate. ``--record PAGE/ID``
writes every other row's ratio to the first into that row of docs/benchmarks/results.json and its
page's table (benchmarks/results_file.py; no target, so "no target"); ``--plot PNG`` draws the
``--workers`` curve (median and IQR against workers, one line per setup, the machine's cores marked):

    python benchmarks/bench_scale.py --batches 8 --warmup 2 --record scaling/ray
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
# Ray reads this when first imported (torchrl imports it with the collectors): without it a cluster
# started on 127.0.0.1 advertises the machine's network address and the driver hangs connecting.
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

sys.path.insert(0, str(Path(__file__).resolve().parent))  # results_file, also when loaded by path
import results_file  # noqa: E402

from rlgrasp.compose import compose_train  # noqa: E402 - after the Ray setting above
from rlgrasp.train.parts import build_parts  # noqa: E402


def bench(setup: str, batches: int, warmup: int, extra: list[str]) -> list[float]:
    tmp = tempfile.mkdtemp()
    overrides = ["experiment=grasp_ppo", f"paths.output_dir={tmp}", *extra]
    cluster = None
    if setup == "process":
        overrides.append("collector=process")
    else:
        overrides += ["collector=ray", "collector.ray.memory_per_worker_gb=0.5"]
        if setup == "ray_2nodes":
            from ray.cluster_utils import Cluster  # an optional extra: only the Ray setups need it

            node = {"num_cpus": 1, "node_ip_address": "127.0.0.1"}
            cluster = Cluster(initialize_head=True, head_node_args={**node, "include_dashboard": False})
            cluster.add_node(**node)
            cluster.wait_for_nodes()
            overrides.append(f"collector.ray.address={cluster.address}")
    cfg = compose_train(overrides)
    collector = build_parts(cfg).make_collector(0, os.path.join(tmp, "errors"))
    rates = []
    try:
        it = iter(collector)
        for i in range(warmup + batches):
            t0 = time.perf_counter()
            batch = next(it)
            collector.update_policy_weights_()
            if i >= warmup:
                rates.append(batch.numel() / (time.perf_counter() - t0))
    finally:
        collector.shutdown()
        if setup != "process":
            import ray  # an optional extra, as above

            ray.shutdown()
        if cluster is not None:
            cluster.shutdown()
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, default=8)
    parser.add_argument("--warmup", type=int, default=2)
    parser.add_argument("--setups", nargs="+", default=["process", "ray", "ray_2nodes"])
    parser.add_argument(
        "--workers", type=int, nargs="+", help="a curve over collector.num_workers (8 envs each by default)"
    )
    parser.add_argument("--plot", type=Path, help="with --workers: the PNG of frames/s against workers")
    parser.add_argument("overrides", nargs="*", help="training overrides, e.g. collector.envs_per_worker=4")
    results_file.add_options(parser)
    args = parser.parse_args()
    if args.plot and not args.workers:
        parser.error("--plot draws the --workers curve: give --workers too")
    medians = {}
    curves: dict[str, list[tuple[int, list[float]]]] = {}
    print("| backend | workers | frames/s median | IQR | batches | vs first row |")
    print("|---|---|---|---|---|---|")
    first = None
    for setup in args.setups:
        for workers in args.workers or [None]:
            extra = [f"collector.num_workers={workers}"] if workers else []
            rates = bench(setup, args.batches, args.warmup, [*args.overrides, *extra])
            q = statistics.quantiles(rates, n=4)
            med = statistics.median(rates)
            first = first or med
            row = [setup, workers or "config", f"{med:,.0f}", f"{q[0]:,.0f}-{q[2]:,.0f}", len(rates)]
            print("| " + " | ".join(map(str, row)) + f" | {med / first:.2f} |", flush=True)
            medians[setup if workers is None else f"{setup} x{workers}"] = med
            curves.setdefault(setup, []).append((workers, rates))
    if args.plot:
        plot_workers(curves, args.plot)
    if args.record:
        results_file.record(*args.record, record_text(medians), "no target", load=args.record_load)


def plot_workers(curves: dict[str, list[tuple[int, list[float]]]], out: Path) -> None:
    """Frames/s against workers: each setup's median with its interquartile range, and a line at the
    machine's core count (past it the workers share the cores, so the curve flattens there)."""
    from rlgrasp.utils import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.6))
    for setup, points in curves.items():
        workers = [w for w, _ in points]
        medians = [statistics.median(r) for _, r in points]
        quartiles = [statistics.quantiles(r, n=4) for _, r in points]
        low = [m - q[0] for m, q in zip(medians, quartiles)]
        high = [q[2] - m for m, q in zip(medians, quartiles)]
        ax.errorbar(workers, medians, yerr=[low, high], marker="o", capsize=3, label=setup)
    cores = os.cpu_count() or 1
    ax.axvline(cores, color="grey", linestyle=":", label=f"{cores} cores")
    ax.set_xlabel("collector.num_workers")
    ax.set_ylabel("frames/s (median, IQR)")
    ax.set_xticks(sorted({w for points in curves.values() for w, _ in points}))
    ax.set_ylim(bottom=0)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def record_text(medians: dict[str, float]) -> str:
    """The results table's ``measured`` cell: each later setup's median frames/s as a share of the
    first's, e.g. "ray 0.94, ray_2nodes 0.89 of process's frames/s"."""
    names = list(medians)
    if len(names) == 1:
        return f"{names[0]} {medians[names[0]]:,.0f} frames/s"
    base = medians[names[0]]
    return ", ".join(f"{n} {medians[n] / base:.2f}" for n in names[1:]) + f" of {names[0]}'s frames/s"


if __name__ == "__main__":
    main()
