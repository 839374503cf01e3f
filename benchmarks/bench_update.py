"""What one update costs the learner, per frame: the ceiling on frames/s however many workers
collect (with ``collector.overlap`` a batch takes about max(collection, update + evaluation)).

    python benchmarks/bench_update.py [--threads 1 2] [--minibatch 512 1024] [--repeats 3] [--compile]
        [overrides ...]
    python benchmarks/bench_update.py [--threads 1 2] [--steps 50] [--env-steps 500] experiment=grasp_sac

PPO (default ``experiment=grasp_ppo``): collects one batch of training's size in-process, then
times ``PPOLearner.update`` on it for each torch thread count and minibatch size, with the target-KL
stop off so that every update runs all its epochs (training stops some updates early: a bound).
``--compile`` adds a row per setting with the loss under ``torch.compile`` (TorchRL's sota PPO
compiles its update; training here does not): its first update, which compiles, is timed apart.

SAC (an experiment whose algorithm is SAC or a subclass of it, ``algo=tqc``): fills the replay
buffer with frames collected in-process, times one gradient step (``SAC._step``) for each torch thread
count, and sets the learner's cost per env frame (a step's time x ``algo.optim.utd_ratio``) against the
env's (one env stepped in this process with random actions, divided by the workers that step envs in
parallel): the larger of the two bounds a run in which learner and workers overlap. The env figure
leaves out the actor's and TorchRL's share of a worker's time, so the ceiling it implies is
optimistic. ``--profile`` adds, on the last thread count, where a step goes: its parts timed one by
one (sampling, a camera's augmenting and encoding, each loss, the optimizers) and the ops that take
the most time (``torch.profiler``). Like training's learner, it keeps glibc's freed memory
(``rlgrasp.utils.keep_freed_memory``); ``--malloc-defaults`` times it with the allocator as it starts:

    python benchmarks/bench_update.py --threads 2 --steps 20 --profile experiment=grasp_vision_sac_rgb_demos

``--peer sb3`` adds, per thread count, Stable-Baselines3's gradient step on the same shapes
(``peer_step.py``: SB3's SAC, sb3-contrib's TQC for ``algo=tqc``; the keywords ``bench_peer.sb3_kwargs``
maps, a replay of as many random transitions) timed in the same process, the two sides alternating over
``--rounds`` rounds of ``--steps`` steps each, and the ratio of their medians: on a loaded machine the
absolute ms move from run to run, the ratio much less:

    python benchmarks/bench_update.py --threads 1 2 --steps 50 --peer sb3 experiment=grasp_tqc
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout, uninstalled
sys.path.insert(1, str(Path(__file__).resolve().parent))  # results_file, peer_step
import results_file
import torch

from rlgrasp.algos.ppo.learner import PPOLearner
from rlgrasp.compose import compose_train
from rlgrasp.train.algorithm import algorithm_class
from rlgrasp.train.collection.collectors import collector_backend
from rlgrasp.train.parts import build_parts
from rlgrasp.utils import keep_freed_memory


def collect(overrides: list[str], frames: int) -> tuple[Any, Any]:
    """The config as training composes it, and ``frames`` frames collected by one in-process
    worker (as many envs as a training worker steps, each for more steps)."""
    cfg = compose_train(overrides)
    single = compose_train(
        [
            *overrides,
            "collector=single",
            f"collector.steps_per_env={max(1, frames // cfg.collector.envs_per_worker)}",
        ]
    )
    torch.manual_seed(0)
    collector = build_parts(single).make_collector()
    batch = next(iter(collector))
    collector.shutdown()
    return cfg, batch


def ppo_table(cfg: Any, batch: Any, args: argparse.Namespace) -> None:
    """One row per thread count, minibatch size (and with ``--compile``, compiled or not)."""
    frames = batch.numel()
    print(
        f"{frames:,} frames per batch, {cfg.algo.optim.epochs} epochs, hidden {list(cfg.model.hidden_sizes)}"
    )
    print(
        "| torch threads | minibatch | loss | first update, s | ms per update | ms per frame"
        " | learner ceiling, frames/s |"
    )
    print("|---|---|---|---|---|---|---|")
    for threads in args.threads:
        torch.set_num_threads(threads)
        for minibatch in args.minibatch:
            for compiled in (False, True) if args.compile else (False,):
                algo = copy.deepcopy(cfg.algo)
                algo.optim.minibatch_size, algo.schedule.target_kl = minibatch, None
                parts = build_parts(cfg)
                learner = PPOLearner(parts.actor, parts.critic, parts.norm, algo, torch.device("cpu"), True)
                if compiled:
                    learner.loss = torch.compile(learner.loss)
                t0 = time.perf_counter()
                learner.update(batch.clone())  # warm-up; with compile, the compilation
                first = time.perf_counter() - t0
                t0 = time.perf_counter()
                for _ in range(args.repeats):
                    learner.update(batch.clone())
                ms = (time.perf_counter() - t0) / args.repeats * 1000
                row = [
                    threads,
                    minibatch,
                    "compiled" if compiled else "eager",
                    f"{first:.1f}",
                    f"{ms:.0f}",
                    f"{ms / frames:.3f}",
                    f"{frames / ms * 1000:,.0f}",
                ]
                print("| " + " | ".join(map(str, row)) + " |", flush=True)


def warm_sac(cfg: Any, batch: Any, threads: int) -> Any:
    """A fresh ``SAC`` (or the subclass ``algo._target_`` names: TQC) on ``threads`` torch threads whose
    replay holds ``batch`` (and whose normalizer has seen it), after a few untimed steps."""
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    algo = algorithm_class(cfg.algo)(cfg, build_parts(cfg), torch.device("cpu"))
    algo.remember(batch)  # a camera's images too; with algo.her, each transition's episode
    for _ in range(3):  # warm-up: the optimizers' state, the allocator
        algo._step()
    return algo


def step_ms(algo: Any, steps: int) -> float:
    """ms per gradient step of ``algo``, over ``steps`` steps."""
    t0 = time.perf_counter()
    for _ in range(steps):
        algo._step()
    return (time.perf_counter() - t0) / steps * 1000


def sac_step_ms(cfg: Any, batch: Any, threads: int, steps: int) -> float:
    """ms per gradient step of a fresh, warmed-up ``SAC`` (``warm_sac``)."""
    return step_ms(warm_sac(cfg, batch, threads), steps)


def peer_table(cfg: Any, batch: Any, args: argparse.Namespace) -> list[tuple[int, float, float]]:
    """Per thread count: rlgrasp's gradient step and SB3's on the same shapes (``peer_step``), each
    the median over ``--rounds`` rounds that alternate the two, and their ratio. Returns
    ``(threads, rlgrasp ms, SB3 ms)`` per thread count."""
    from peer_step import peer_model, peer_step_ms

    a, spec = cfg.algo, build_parts(cfg).spec
    print(
        f"\npeer: SB3 {a.name.upper()} on the same shapes (obs {spec['obs_dim']}, action "
        f"{len(spec['action_low'])}, minibatch {a.optim.batch_size}, {a.loss.num_critics} critics "
        f"{list(a.critic.hidden_sizes)}), {batch.numel():,} random transitions; median of {args.rounds} "
        f"rounds of {args.steps} steps"
    )
    print("| torch threads | rlgrasp ms per step | SB3 ms per step | rlgrasp / SB3 |\n|---|---|---|---|")
    rows = []
    for threads in args.threads:
        ours = warm_sac(cfg, batch, threads)
        torch.manual_seed(0)
        peer = peer_model(cfg, spec["obs_dim"], len(spec["action_low"]), batch.numel())
        times: dict[str, list[float]] = {"ours": [], "peer": []}
        for _ in range(args.rounds):
            times["ours"].append(step_ms(ours, args.steps))
            times["peer"].append(peer_step_ms(peer, args.steps, a.optim.batch_size))
        mine, theirs = (statistics.median(times[k]) for k in ("ours", "peer"))
        print(f"| {threads} | {mine:.1f} | {theirs:.1f} | {mine / theirs:.2f} |", flush=True)
        rows.append((threads, mine, theirs))
    return rows


def record_peer(rows: list[tuple[int, float, float]], args: argparse.Namespace) -> None:
    """``--record PAGE/ID``: the ratio per thread count into results.json, met when rlgrasp's step
    costs no more than SB3's at every one."""
    parts = [f"{t} thread{'s' if t > 1 else ''}: {m:.1f} / {p:.1f} ms ({m / p:.2f})" for t, m, p in rows]
    text = ", ".join(parts)
    met = results_file.met_of([m <= p for _, m, p in rows])
    results_file.record(*args.record, f"rlgrasp / SB3 per gradient step, {text}", met, load=args.record_load)


#: The parts of a gradient step that ``--profile`` times, each by the method that does it (on the
#: learner, its loss, its optimizers). "augment" runs inside "augment + encode"; what no part names
#: (the losses' backward, above all) is the step's remainder.
STEP_PARTS = (
    ("sample the minibatch", "", "_sample"),
    ("augment + encode the images", "", "_inputs"),
    ("  of it: augment", "", "_augmented"),
    ("critics' loss (forward)", "loss", "critic_loss"),
    ("actor's loss (forward)", "loss", "actor_loss"),
    ("optimizer steps", "optimizers", "step"),
    ("target critics' update", "loss", "soft_update"),
)


def time_parts(algo: Any) -> dict[str, float]:
    """Wrap each of ``STEP_PARTS`` on this learner instance (the benchmark's patch; training's
    classes stay as they are) so that every call adds its seconds to the returned dict."""
    seconds: dict[str, float] = {}

    def wrap(owner: Any, method: str, label: str) -> None:
        inner = getattr(owner, method)

        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                seconds[label] = seconds.get(label, 0.0) + time.perf_counter() - t0

        setattr(owner, method, timed)

    for label, attr, method in STEP_PARTS:
        owners = getattr(algo, attr) if attr else algo
        for owner in owners.values() if isinstance(owners, dict) else [owners]:
            wrap(owner, method, label)
    return seconds


def sac_profile(cfg: Any, batch: Any, threads: int, steps: int) -> None:
    """Print a gradient step's time part by part (``STEP_PARTS``), then the ops that take the most
    time over 5 steps (``torch.profiler``)."""
    from torch.profiler import ProfilerActivity, profile

    algo = warm_sac(cfg, batch, threads)
    seconds = time_parts(algo)
    step = step_ms(algo, steps)
    print(f"\n{threads} threads: {step:.1f} ms a gradient step, over {steps} steps")
    print("| part of the step | ms | share |\n|---|---|---|")
    named = 0.0
    for label, *_ in STEP_PARTS:
        ms = seconds.get(label, 0.0) / steps * 1000
        named += 0.0 if label.startswith(" ") else ms
        print(f"| {label} | {ms:.1f} | {ms / step:.0%} |")
    rest = step - named
    print(f"| the rest: the losses' backward, bookkeeping | {rest:.1f} | {rest / step:.0%} |")
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(5):
            algo._step()
    print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=12))


def env_ms_per_frame(cfg: Any, steps: int) -> float:
    """ms per step of one env in this process under random actions (no actor, no TorchRL)."""
    env = build_parts(cfg).make_env()
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(20):  # warm-up
        env.step(env.action_space.sample())
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    ms = (time.perf_counter() - t0) / steps * 1000
    env.close()
    return ms


def sac_table(cfg: Any, batch: Any, args: argparse.Namespace) -> None:
    """Per thread count: a gradient step, the learner per frame, the env per frame over the
    workers, which of the two bounds, and the ceiling it implies."""
    a, workers = cfg.algo, max(1, cfg.collector.num_workers)
    env_ms = env_ms_per_frame(cfg, args.env_steps)
    print(
        f"replay: {batch.numel():,} frames; minibatch {a.optim.batch_size}, {a.loss.num_critics} critics "
        f"{list(a.critic.hidden_sizes)}, actor {list(cfg.model.hidden_sizes)}, utd_ratio {a.optim.utd_ratio}"
    )
    print(
        f"env: {env_ms:.3f} ms per frame (one env, random actions, {args.env_steps} steps); "
        f"{workers} workers: {env_ms / workers:.3f} ms per frame"
    )
    print(
        "| torch threads | ms per gradient step | learner ms per frame | env ms per frame / workers"
        " | learner / env | bound | ceiling, frames/s |"
    )
    print("|---|---|---|---|---|---|---|")
    for threads in args.threads:
        step_ms = sac_step_ms(cfg, batch, threads, args.steps)
        learner, env = step_ms * a.optim.utd_ratio, env_ms / workers
        bound = "learner" if learner > env else "env"
        row = [
            threads,
            f"{step_ms:.1f}",
            f"{learner:.3f}",
            f"{env:.3f}",
            f"{learner / env:.2f}",
            bound,
            f"{1000 / max(learner, env):,.0f}",
        ]  # overlapped: the slower of the two sets the pace
        print("| " + " | ".join(map(str, row)) + " |", flush=True)
    print(
        f"The ceiling gives the learner and each of the {workers} workers a core of its own; on 2 cores "
        "they share them, and a worker also runs the actor and TorchRL's bookkeeping."
    )
    if args.peer:
        rows = peer_table(cfg, batch, args)
        if args.record:
            record_peer(rows, args)
    if args.profile:
        sac_profile(cfg, batch, args.threads[-1], args.steps)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--minibatch", type=int, nargs="+", default=[512, 1024], help="PPO")
    parser.add_argument("--repeats", type=int, default=3, help="PPO: timed updates per setting, after one")
    parser.add_argument("--compile", action="store_true", help="PPO: also time the loss under torch.compile")
    parser.add_argument("--steps", type=int, default=50, help="SAC: timed gradient steps per thread count")
    parser.add_argument("--env-steps", type=int, default=500, help="SAC: timed steps of one env")
    parser.add_argument("--profile", action="store_true", help="SAC: where a step goes (last thread count)")
    parser.add_argument(
        "--peer", choices=["sb3"], help="SAC/TQC: also time SB3's step on the same shapes, and the ratio"
    )
    parser.add_argument("--rounds", type=int, default=3, help="--peer: alternating rounds per side")
    results_file.add_options(parser)  # with --peer: the ratios into results.json
    parser.add_argument(
        "--malloc-defaults",
        action="store_true",
        help="glibc's allocator as it starts (training's learner calls rlgrasp.utils.keep_freed_memory)",
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides (default experiment=grasp_ppo)")
    args = parser.parse_args()
    if args.record and not args.peer:
        parser.error("--record needs --peer sb3: the row holds rlgrasp's step against SB3's")
    if not args.malloc_defaults:
        keep_freed_memory()

    overrides = args.overrides or ["experiment=grasp_ppo"]
    cfg = compose_train(overrides)
    if _replays(cfg):
        # a replay of a few minibatches (training's batch is small: 128 frames for grasp_sac)
        frames = max(collector_backend(cfg.collector).frames_per_batch, 4 * cfg.algo.optim.batch_size)
        sac_table(*collect(overrides, frames), args)
    else:  # one in-process worker collects the batch training would get from all of them
        ppo_table(*collect(overrides, collector_backend(cfg.collector).frames_per_batch), args)


def _replays(cfg: Any) -> bool:
    """Whether the experiment's algorithm is SAC or one of its subclasses (TQC): timed by its step."""
    from rlgrasp.algos.sac import SAC

    return issubclass(algorithm_class(cfg.algo), SAC)


if __name__ == "__main__":
    main()
