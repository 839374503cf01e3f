"""How well a camera run's encoder says where the object is: the first keypoint map (the one the
``algo.terms.object_map`` term trains) against the object's pixels.

Two measurements, one per mode:

- rollouts (default): the run's policy acts for ``--episodes`` seeded episodes on the held-out meshes
  with ``--visual``; on each of the first 20 frames that show the object, the map's cross-entropy
  against the object's pixels (the term's loss; its floor is the target's own entropy, printed
  beside it) and how often the map's peak falls on the target's, split by plain and textured ground.
- ``--fit STEPS``: a fresh encoder of the run's geometry (or ``--model`` overrides) trained on that
  loss alone, on the run's newest replay file, augmented as the run augments; the cross-entropy and
  the expected keypoint's distance to the object's centre (pixels) on 1,024 held-back frames, and
  the milliseconds a step of 256 images takes on 2 threads: what the encoder can learn to locate
  with nothing else asking of it.

    python benchmarks/locate_object.py outputs/bench_learning/vision/<run> --visual heldout
    python benchmarks/locate_object.py <run> --fit 1500 --model '{"channels": [32, 64, 64]}'
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.algos.sac.replay_files import ReplayFiles
from rlgrasp.compose import compose_train
from rlgrasp.envs.factory import env_factory
from rlgrasp.models.cnn import build_vision_actor, vision_net
from rlgrasp.policy_file import load_checkpoint
from rlgrasp.vision.augment import augment_images
from rlgrasp.vision.object_map import MapTap, last_conv, map_cross_entropy, map_window


def _encoder(spec: dict, model_cfg, weights: dict | None):
    actor = build_vision_actor(spec, model_cfg, deterministic=True)
    if weights is not None:
        actor.load_state_dict(weights)
    encoder = vision_net(actor.eval()).encoders["rgb"]
    tap = MapTap()
    last_conv(encoder).register_forward_hook(tap)
    return actor, encoder, tap


def _cross_entropy(
    maps: torch.Tensor, cells: torch.Tensor, window: tuple[float, int], image: int = 64
) -> tuple:
    """Per image: the term's cross-entropy (``map_cross_entropy``), the target's own entropy (its
    floor), whether the map's peak is the target's, and whether the object shows."""
    cross, target, shows = map_cross_entropy(maps, cells, image, window)
    entropy = -(target * target.clamp_min(1e-12).log()).sum(-1)
    return cross, entropy, maps[:, 0].flatten(1).argmax(-1) == target.argmax(-1), shows


def rollouts(run: Path, visual: str, episodes: int) -> None:
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    spec, cfg = state["spec"], OmegaConf.create(state["config"])
    actor, _, tap = _encoder(spec, cfg.model, state["actor"])
    env_cfg = compose_train(
        [f"experiment={cfg.experiment_name}", f"env.sim.visual={visual}", "objects=random_urdfs_test"]
    )
    env = env_factory(env_cfg.env)()
    start, stop = spec["privileged_parts"]["object_cells"]
    window = map_window(cfg.model.kernel_sizes, cfg.model.strides)
    rows: dict[str, list] = {"plain": [], "textured": []}
    for seed in range(episodes):
        obs, info = env.reset(seed=seed)
        ground = "textured" if info["randomization"]["visual_ground_texture"] >= 0 else "plain"
        for step in range(50):
            td = TensorDict(
                {
                    "observation": torch.as_tensor(obs["state"]).float()[None],
                    "rgb": torch.as_tensor(obs["rgb"])[None],
                },
                [1],
            )
            with torch.no_grad():
                action = actor(td)["action"][0].numpy()
            cells = torch.as_tensor(obs["privileged"][start:stop]).float()[None]
            cross, entropy, hit, shows = _cross_entropy(tap.maps, cells, window, obs["rgb"].shape[-1])
            if step < 20 and shows.item():
                rows[ground].append((cross.item(), entropy.item(), float(hit.item())))
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    env.close()
    for ground, values in rows.items():
        v = np.array(values)
        print(
            f"{run.name} visual={visual} {ground}: {len(v)} frames, cross-entropy {v[:, 0].mean():.2f} "
            f"(floor {v[:, 1].mean():.2f}), peak on the object {v[:, 2].mean():.2f}"
        )


def fit(run: Path, steps: int, model: dict) -> None:
    torch.manual_seed(0)
    torch.set_num_threads(2)
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    spec, cfg = state["spec"], OmegaConf.create(state["config"])
    for key, value in model.items():
        cfg.model[key] = value
    _, encoder, tap = _encoder(spec, cfg.model, None)
    newest = ReplayFiles(run).chunks()[-1][2]  # one file: the run's last transitions
    data = torch.load(newest, map_location="cpu", weights_only=True)["data"]
    start, stop = spec["privileged_parts"]["object_cells"]
    rgb, mask, cells = data["rgb"], data["ground_mask"], data["privileged"][:, start:stop].float()
    held_back, n = torch.arange(len(rgb) - 1024, len(rgb)), len(rgb) - 2048
    window = map_window(cfg.model.kernel_sizes, cfg.model.strides)
    per_side = round(cells.shape[-1] ** 0.5)  # the camera's object cells: per_side x per_side
    pixels = rgb.shape[-1] / per_side  # a cell's side in pixels
    centres = torch.arange(per_side) * pixels + (pixels - 1) / 2
    cell_xy = torch.stack(torch.meshgrid(centres, centres, indexing="ij"), -1).reshape(-1, 2)
    aug = cfg.algo.augment
    optimizer = torch.optim.Adam(encoder.conv.parameters(), lr=1e-3)

    def measure(index: torch.Tensor, augment: bool) -> tuple[torch.Tensor, torch.Tensor]:
        images = rgb[index]
        if augment:
            images = augment_images(
                images, "rgb", aug.kind, aug.grey, aug.shift, 0.0, mask[index], aug.ground_swap
            )
        encoder(images)
        cross, _, _, shows = _cross_entropy(tap.maps, cells[index], window, rgb.shape[-1])
        size = tap.maps.shape[-1]
        ticks = torch.arange(size) * window[1] + window[0]
        grid = torch.stack(torch.meshgrid(ticks, ticks, indexing="ij"), -1).reshape(-1, 2)
        expected = torch.softmax(tap.maps[:, 0].flatten(1), -1) @ grid
        centre = (cells[index] / cells[index].sum(-1, keepdim=True).clamp_min(1e-8)) @ cell_xy
        error = (expected - centre).norm(dim=-1)
        return (cross * shows).sum() / shows.sum(), (error * shows).sum() / shows.sum()

    for step in range(steps + 1):
        if step % (steps // 3) == 0:
            with torch.no_grad():
                cross, error = measure(held_back, False)
            print(
                f"{model or 'as the run'}: step {step}, cross-entropy {cross:.2f}, "
                f"keypoint {error:.2f} px off"
            )
        if step == 20:
            t0 = time.perf_counter()
        loss, _ = measure(torch.randint(n, (256,)), True)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    print(f"{model or 'as the run'}: {(time.perf_counter() - t0) / (steps - 20) * 1000:.1f} ms a step")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--visual", default="default")
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--fit", type=int, default=0, help="train a fresh encoder this many steps instead")
    parser.add_argument("--model", type=json.loads, default={}, help="model overrides for --fit, JSON")
    args = parser.parse_args()
    if args.fit:
        fit(args.run, args.fit, args.model)
    else:
        rollouts(args.run, args.visual, args.episodes)


if __name__ == "__main__":
    main()
