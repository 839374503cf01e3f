"""ADR on the learner's side: boundary outcomes in from each batch, ranges out to the workers' envs.

The ranges travel through TorchRL's own channel to a collector's workers, ``collector.map_fn``: it
calls a method on each worker's inner collector (a pipe message to a process worker, a remote call
to a Ray actor, a plain call in process), here ``env.base_env._env.call``, gymnasium's vector-env
call of ``GraspEnv.set_randomization_ranges`` on every env of the worker. ``rlgrasp.train.collection.batches``
pushes them while the workers are idle, with the policy weights, so every batch is collected with one
set of ranges and a seed gives one run.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from omegaconf import OmegaConf
from tensordict import TensorDictBase
from torchrl.collectors import BaseCollector

from rlgrasp.adr import BOUNDS, NOT_BOUNDARY, AdrState
from rlgrasp.envs.randomization import Randomizer
from rlgrasp.train.callbacks import Callback
from rlgrasp.train.tracking.logger import log
from rlgrasp.train.tracking.metrics import finished_mask

#: The run's final ranges, loadable as ``env.randomization=<run dir>/adr_ranges.yaml`` (docs/adr.md).
RANGES_FILE = "adr_ranges.yaml"
#: The worker-side method ``map_fn`` calls: the inner collector's env is
#: ``TransformedEnv(GymWrapper(SyncVectorEnv))`` (``rlgrasp.train.collection.collect.make_batched_env``).
_ENV_CALL = "env.base_env._env.call"


class AdrSync(Callback):
    """The ADR state of one run and its traffic with the collector; beside the loop, its curves, its
    state in each checkpoint and its ranges file."""

    def __init__(self, randomizer: Randomizer, full_length: int | None = None) -> None:
        assert randomizer.adr is not None
        self.settings = randomizer.adr
        names = self.settings.names
        start = {name: (r.low, r.high) for name, r in randomizer.ranges.items() if name in names}
        self.state = AdrState(self.settings, start)
        #: The ranges ADR leaves alone (its base preset's and the spec's own), for the ranges file.
        self.fixed = {name: r for name, r in randomizer.ranges.items() if name not in names}
        self.full_length = full_length

    @classmethod
    def from_env_cfg(cls, env_cfg: Mapping[str, Any], full_length: int | None = None) -> AdrSync | None:
        """An ``AdrSync`` when the env's randomization has an ``adr`` node, else None."""
        spec = env_cfg.get("randomization", "default")
        if OmegaConf.is_config(spec):
            spec = OmegaConf.to_container(spec, resolve=True)
        randomizer = Randomizer(spec)
        return cls(randomizer, full_length) if randomizer.adr is not None else None

    def observe(self, batch: TensorDictBase) -> list[str]:
        """Feed the batch's finished boundary episodes (their success at the end) into the buffers;
        the moves it caused, in words."""
        keys = batch.keys(True)
        if ("next", "adr_boundary") not in keys:
            return []
        done = finished_mask(batch, self.full_length)
        codes = batch["next", "adr_boundary"].reshape(batch.shape)[done]
        success = batch["next", "is_success"].reshape(batch.shape)[done].float()
        moves = []
        for code, ok in zip(codes.tolist(), success.tolist()):  # batch order: deterministic
            if code != NOT_BOUNDARY:
                move = self.state.record(int(code), ok)
                if move:
                    moves.append(move)
        for move in moves:
            log.info("adr: %s", move)
        return moves

    def push(self, collector: BaseCollector) -> None:
        """Give every env of every worker the current ranges (and turn its boundary episodes on)."""
        workers = getattr(collector, "num_workers", None) or getattr(collector, "num_collectors", None) or 1
        args = ("set_randomization_ranges", self.state.range_tuples(), self.settings.boundary_prob)
        collector.map_fn(_ENV_CALL, list_of_args=[args] * workers)

    def scalars(self) -> dict[str, float]:
        """TensorBoard's ``adr/<parameter>/low|high`` and ``adr/entropy``."""
        out = {f"adr/{name}/{BOUNDS[b]}": r[b] for name, r in self.state.ranges.items() for b in (0, 1)}
        out["adr/entropy"] = self.state.entropy()
        return out

    # --- the loop's hooks (rlgrasp.train.callbacks) --------------------------------------------
    def on_batch_end(self, host: Any, metrics: dict[str, float]) -> None:
        metrics.update(self.scalars())

    def state_dict(self) -> dict[str, Any]:
        return {"adr": self.state.state_dict()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if "adr" in state:
            self.state.load_state_dict(state["adr"])

    def on_save(self, run_dir: Path) -> None:
        self.write_ranges(run_dir)  # the ranges reached so far, for rlgrasp-eval

    def write_ranges(self, run_dir: Path) -> Path:
        """Every range of the run as it is now, ADR's and the others, as a file ``randomization=``
        loads: the episodes it gives are drawn as the run's own are."""
        log = {p.name: p.log for p in self.settings.params}
        ranges = {name: (r.low, r.high, r.log) for name, r in self.fixed.items()}
        ranges.update({name: (*r, log[name]) for name, r in self.state.ranges.items()})
        spec = {
            "preset": "none",
            **{
                name: {"low": float(low), "high": float(high), **({"log": True} if log else {})}
                for name, (low, high, log) in ranges.items()
            },
        }
        path = Path(run_dir) / RANGES_FILE
        header = "# The ADR ranges this run reached: rlgrasp-eval ... +env.randomization=<this file>\n"
        path.write_text(header + yaml.safe_dump(spec, sort_keys=False))
        return path
