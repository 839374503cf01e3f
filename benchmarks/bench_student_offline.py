"""Camera students compared offline: the same recorded frames, the same wall time, validation losses.

A distillation run takes 15-30 minutes and one success rate; this takes minutes per variant and
says which encoder settings generalize. Once: the objects teacher drives episodes (half of them with
noise on its actions, so the frames include states it would not visit) and labels every frame;
training frames come from `train_mix` under `visual=default`, validation frames from other seeds
(`default`) and from `random_urdfs_test` under `visual=heldout`. Then each variant (config overrides
of the student) regresses onto the training frames for `--seconds`, and its mean squared error to
the teacher's actions is printed on each validation set. A lower loss is not a higher success rate:
use it to choose what to run in full.

    python benchmarks/bench_student_offline.py [--train-episodes 800] [--seconds 200] \
        [--variant base= --variant "wide=algo.augment.shift=4 model.channels=[32,64,64]" ...]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.compose import compose_train
from rlgrasp.demos.bc import mse_bc_loss
from rlgrasp.envs.factory import env_factory
from rlgrasp.models.cnn import actor_norm, build_vision_actor
from rlgrasp.models.spec import vision_spec
from rlgrasp.policy_file import resolve_policy_path
from rlgrasp.vision.augment import augment
from rlgrasp.vision.dagger import load_teacher

# The RGB experiment with the flat encoder (model=cnn), which the docs' tables call "base"; a variant
# adds "model.pooling=keypoints ..." for the experiment's own keypoint encoder.
BASE = [
    "experiment=grasp_objects_vision_distill_rgb",
    "model=cnn",
    "paths.output_dir=/tmp/bench_student_offline",
]
SETS = {  # name: (first seed, overrides)
    "train": (0, []),
    "val_default": (500_000, []),
    "val_heldout": (600_000, ["objects=random_urdfs_test", "visual=heldout"]),
}
IMAGE = "rgb"


# --- recording ---------------------------------------------------------------------------------
def _record(job: tuple[list[str], list[int]]) -> dict[str, torch.Tensor]:
    """Episodes of the teacher (noisy on every other one), each frame labelled with its clean action."""
    overrides, seeds = job
    torch.set_num_threads(1)
    cfg = compose_train([*BASE, *overrides])
    make_env = env_factory(cfg.env)
    teacher, _ = load_teacher(resolve_policy_path(cfg.algo.teacher), vision_spec(make_env), cfg.env)
    env, rng = make_env(), np.random.default_rng(seeds[0])
    low, high = env.action_space.low, env.action_space.high
    frames: dict[str, list] = {"state": [], IMAGE: [], "label": []}
    for seed in seeds:
        obs, _ = env.reset(seed=int(seed))
        noise, done = 0.4 * (seed % 2), False
        while not done:
            with torch.no_grad():
                privileged = torch.as_tensor(obs["privileged"])[None]
                label = teacher(TensorDict({"privileged": privileged}, [1]))["action"][0].numpy()
            for key, value in (("state", obs["state"]), (IMAGE, obs[IMAGE]), ("label", label)):
                frames[key].append(value)
            action = np.clip(label + rng.normal(0, noise, label.shape), low, high)
            obs, _, terminated, truncated, _ = env.step(action.astype(np.float32))
            done = terminated or truncated
    env.close()
    return {k: torch.as_tensor(np.array(v)) for k, v in frames.items()}


def record(name: str, episodes: int, cache: Path) -> dict[str, torch.Tensor]:
    """One set, recorded by two worker processes (or read from ``cache`` if recorded before)."""
    path = cache / f"{name}_{episodes}.pt"
    if path.exists():
        return torch.load(path)
    first, overrides = SETS[name]
    seeds = list(range(first, first + episodes))
    with mp.get_context("spawn").Pool(2) as pool:
        parts = pool.map(_record, [(overrides, seeds[i::2]) for i in range(2)])
    data = {k: torch.cat([p[k] for p in parts]) for k in parts[0]}
    cache.mkdir(parents=True, exist_ok=True)
    torch.save(data, path)
    return data


# --- training ----------------------------------------------------------------------------------
def _minibatch(data: dict[str, torch.Tensor], index: torch.Tensor) -> TensorDict:
    return TensorDict(
        {
            "observation": data["state"][index].float(),
            IMAGE: data[IMAGE][index],
            "action": data["label"][index].float(),
        },
        [len(index)],
    )


@torch.no_grad()
def validation_loss(loss_fn, data: dict[str, torch.Tensor]) -> float:
    total = 0.0
    for index in torch.arange(len(data["label"])).split(1000):
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            total += loss_fn(_minibatch(data, index))["loss_bc"].item() * len(index)
    return total / len(data["label"])


def train_variant(overrides: list[str], sets: dict[str, dict], seconds: float) -> dict[str, float]:
    """Regress a fresh student onto the training frames for ``seconds``; its losses."""
    torch.manual_seed(0)
    cfg = compose_train([*BASE, *overrides])
    a, train = cfg.algo, sets["train"]
    student = build_vision_actor(vision_spec(env_factory(cfg.env)), cfg.model)
    actor_norm(student).update(train["state"])
    loss_fn, optimizer = mse_bc_loss(student), torch.optim.Adam(student.parameters(), lr=a.optim.lr)
    start, steps, recent = time.monotonic(), 0, []
    while (elapsed := time.monotonic() - start) < seconds:
        for group in optimizer.param_groups:  # annealed over the budget, as a run anneals over its frames
            group["lr"] = a.optim.lr * max(a.schedule.min_lr_frac, 1.0 - elapsed / seconds)
        sample = augment(
            _minibatch(train, torch.randint(len(train["label"]), (a.optim.minibatch_size,))),
            a.augment,
            a.augment_grey,
            a.augment_shift,
        )
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            loss = loss_fn(sample)["loss_bc"]
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        steps, recent = steps + 1, [*recent[-49:], loss.item()]
    student.eval()
    return {
        "updates": steps,
        "train (augmented)": sum(recent) / len(recent),
        **{name: validation_loss(loss_fn, data) for name, data in sets.items() if name != "train"},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train-episodes", type=int, default=800)
    parser.add_argument("--val-episodes", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=200.0)
    parser.add_argument(
        "--cache",
        type=Path,
        default=Path("outputs/bench_student_offline"),
        help="recorded frames, reused by set name and episode count (new teacher: delete)",
    )
    parser.add_argument(
        "--variant",
        action="append",
        metavar="NAME=[OVERRIDE ...]",
        help="default: base= and shift=algo.augment.shift=4",
    )
    args = parser.parse_args()
    variants = args.variant or ["base=", "shift=algo.augment.shift=4"]
    sets = {
        name: record(name, args.train_episodes if name == "train" else args.val_episodes, args.cache)
        for name in SETS
    }
    counts = ", ".join(f"{name} {len(data['label']):,}" for name, data in sets.items())
    print(f"frames: {counts}; {args.seconds:.0f} s per variant")
    for variant in variants:
        name, _, spec = variant.partition("=")
        result = train_variant(spec.split(), sets, args.seconds)
        print(
            f"{name:12s} "
            + "  ".join(f"{k} {v:.4f}" if isinstance(v, float) else f"{k} {v}" for k, v in result.items()),
            flush=True,
        )


if __name__ == "__main__":
    main()
