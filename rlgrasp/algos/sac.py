"""Soft actor-critic on the training core (``algo=sac``), with demonstrations in the replay (RLPD).

TorchRL provides the loss (``SACLoss``: twin or ensemble critics, the entropy temperature learned
towards a target entropy, target critics), the target-network updater (``SoftUpdate``) and the
replay buffers. This module adds what they lack for rlgrasp: the update-to-data ratio kept across
batches of any size, symmetric sampling of demonstrations beside online data (Ball et al. 2023:
each minibatch half and half), critics that read the actor's running observation normalizer, and a
replay buffer that a resumed run continues with.

The actor is the parts' TanhNormal policy, so evaluation, export, enjoy and sweeps take a SAC
checkpoint as they take a PPO one. The workers keep collecting the next batch while the learner
updates on this one (``collector.overlap``): off-policy, one batch of lag costs nothing.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.objectives import SACLoss, SoftUpdate

from rlgrasp.models.mlp import ACTIVATIONS, OBS_KEY, RunningNorm
from rlgrasp.train.algorithm import Algorithm, finite_or_raise

#: The entries a transition keeps in the replay buffer (the collector's batch has more).
TRANSITION_KEYS = (OBS_KEY, "action", ("next", OBS_KEY), ("next", "reward"), ("next", "done"),
                   ("next", "terminated"))
#: The replay buffer's file in the run directory (plain tensors, read with ``weights_only=True``).
REPLAY_FILE = "replay.pt"


class QNet(nn.Module):
    """Q(s, a): an MLP on the normalized observation and the action, LayerNorm after each hidden
    layer when asked (RLPD: what keeps critics stable at several updates per frame).

    The normalizer is the actor's, held by reference and not as a submodule: ``SACLoss`` copies a
    critic's parameters and buffers into its ensemble, and a copied normalizer would stop following
    the running statistics the actor (and so the deployed policy) uses."""

    def __init__(self, norm: RunningNorm, obs_dim: int, act_dim: int, hidden: list[int], activation: str,
                 layer_norm: bool) -> None:
        super().__init__()
        object.__setattr__(self, "norm", norm)  # a reference, not a submodule (see above)
        layers: list[nn.Module] = []
        width = obs_dim + act_dim
        for size in hidden:
            layers += [nn.Linear(width, size), *([nn.LayerNorm(size)] if layer_norm else []),
                       ACTIVATIONS[activation]()]
            width = size
        layers.append(nn.Linear(width, 1))
        self.mlp = nn.Sequential(*layers)

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.mlp(torch.cat([self.norm(observation), action], dim=-1))


def build_qvalue(norm: RunningNorm, spec: dict[str, Any], algo_cfg: Any) -> TensorDictModule:
    net = QNet(norm, spec["obs_dim"], len(spec["action_low"]), list(algo_cfg.critic_hidden_sizes),
               algo_cfg.critic_activation, algo_cfg.critic_layer_norm)
    return TensorDictModule(net, in_keys=[OBS_KEY, "action"], out_keys=["state_action_value"])


class SAC(Algorithm):
    """SAC, optionally with demonstrations sampled beside online data (RLPD)."""

    name = "sac"

    def __init__(self, cfg: Any, parts: Any, device: torch.device) -> None:
        super().__init__(cfg, parts, device)
        a = cfg.algo
        self.norm = parts.norm
        act_dim = len(parts.spec["action_low"])
        self.loss = SACLoss(
            self.actor, build_qvalue(self.norm, parts.spec, a).to(device),
            num_qvalue_nets=a.num_critics, loss_function="l2", alpha_init=a.alpha_init,
            target_entropy=a.target_entropy if a.target_entropy is not None else -float(act_dim),
            delay_qvalue=True,
        )
        self.loss.make_value_estimator(gamma=a.gamma)
        self.target_update = SoftUpdate(self.loss, tau=a.tau)
        self.optimizers = {
            "actor": torch.optim.Adam(_trainable(self.loss.actor_network_params), lr=a.actor_lr),
            "critic": torch.optim.Adam(_trainable(self.loss.qvalue_network_params), lr=a.critic_lr),
            "alpha": torch.optim.Adam([self.loss.log_alpha], lr=a.alpha_lr),
        }
        self.demos = self._demos() if a.get("demos") else None
        online = a.batch_size - (self.demos.batch_size if self.demos is not None else 0)
        self.replay = _buffer(a.buffer_frames, online, device)
        self.owed = 0.0  # gradient steps due but not yet taken (the ratio is kept across batches)
        self.replay_file: Path | None = None

    def _demos(self) -> TensorDictReplayBuffer:
        """The demonstrations as transitions in a buffer of their own (read, and refused, before any
        worker starts)."""
        from rlgrasp.demos.dataset import demo_transitions, demos_for  # demos sit above the algorithms

        a = self.cfg.algo
        frames = demo_transitions(demos_for(a.demos, self.parts.make_env, self.cfg.env), self.cfg.env)
        demos = _buffer(frames.numel(), min(a.batch_size - 1, max(1, round(a.batch_size * a.demo_ratio))),
                        self.device)
        demos.extend(frames.to(self.device))
        return demos

    def update(self, batch: TensorDictBase, frames: int) -> dict[str, float]:
        """Store the batch, then take ``utd_ratio`` gradient steps per new frame once the buffer
        holds ``learning_starts`` frames (the steps not taken before are not made up)."""
        a = self.cfg.algo
        t0 = time.perf_counter()
        flat = batch.reshape(-1)
        self.norm.update(flat[OBS_KEY])
        self.replay.extend(flat.select(*TRANSITION_KEYS).to(self.device))
        if len(self.replay) < a.learning_starts:
            return {"charts/replay_frames": float(len(self.replay))}
        self.owed += a.utd_ratio * flat.numel()
        steps = int(self.owed)
        self.owed -= steps
        sums: dict[str, float] = {}
        for _ in range(steps):
            for key, value in self._step().items():
                sums[key] = sums.get(key, 0.0) + value
        metrics = {k: v / max(steps, 1) for k, v in sums.items()}
        metrics["charts/replay_frames"] = float(len(self.replay))
        metrics["charts/gradient_steps"] = float(steps)
        metrics["time/train_s"] = time.perf_counter() - t0
        return metrics

    def _sample(self) -> TensorDictBase:
        """A minibatch: online transitions, and with demonstrations ``demo_ratio`` of it theirs."""
        if self.demos is None:
            return self.replay.sample()
        return torch.cat([self.replay.sample(), self.demos.sample()])

    def _step(self) -> dict[str, float]:
        """One gradient step of the critics, the actor (every ``actor_every`` steps) and the
        temperature, then the target critics' soft update."""
        a = self.cfg.algo
        losses = self.loss(self._sample())
        self.updates += 1
        actor_step = self.updates % a.actor_every == 0
        total = losses["loss_qvalue"] + (losses["loss_actor"] + losses["loss_alpha"] if actor_step else 0.0)
        finite_or_raise(total.detach(), "SAC loss")
        for opt in self.optimizers.values():
            opt.zero_grad(set_to_none=True)
        total.backward()
        self.optimizers["critic"].step()
        if actor_step:
            self.optimizers["actor"].step()
            self.optimizers["alpha"].step()
        self.target_update.step()
        keys = ("loss_qvalue", "loss_actor", "alpha", "entropy")
        return {key: float(losses[key].detach()) for key in keys}

    def trained_parameters(self) -> list[torch.nn.Parameter]:
        return [*self.actor.parameters(), *_trainable(self.loss.qvalue_network_params)]

    def state_dict(self) -> dict[str, Any]:
        """The critics, their targets, the temperature and the optimizers (the replay buffer goes
        to its own file, ``save_extra``)."""
        return {
            "sac": {
                "loss": self.loss.state_dict(),
                "optimizers": {k: o.state_dict() for k, o in self.optimizers.items()},
                "owed": self.owed,
            }
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        saved = state["sac"]
        self.loss.load_state_dict(saved["loss"])
        for key, opt in self.optimizers.items():
            opt.load_state_dict(saved["optimizers"][key])
        self.owed = saved["owed"]
        self.load_replay(Path(self.cfg.paths.output_dir))

    def save_extra(self, run_dir: Any) -> None:
        """The replay buffer, beside the checkpoints: ``replay.pt`` (written atomically)."""
        if not self.cfg.algo.save_replay or len(self.replay) == 0:
            return
        path = Path(run_dir) / REPLAY_FILE
        tmp = path.with_name(f".{path.name}.tmp")
        data = self.replay[:].to("cpu").to_dict()
        torch.save({"frames": len(self.replay), "data": data}, tmp)
        tmp.replace(path)

    def load_replay(self, run_dir: Path) -> None:
        """Continue with the run's replay buffer, or say that the run starts with an empty one."""
        from rlgrasp.train.logger import log

        path = run_dir / REPLAY_FILE
        if not path.is_file():
            log.warning("no %s in %s: the resumed run starts with an empty replay buffer",
                        REPLAY_FILE, run_dir)
            return
        saved = torch.load(path, map_location="cpu", weights_only=True)
        data = TensorDict(saved["data"], batch_size=[saved["frames"]])
        self.replay.extend(data.to(self.device))
        log.info("replay buffer: %s frames from %s", f"{len(self.replay):,}", path)


def _trainable(params: TensorDictBase) -> list[torch.Tensor]:
    """The tensors a loss's parameters hold that take gradients (not the normalizer's statistics)."""
    return [p for p in params.values(True, True) if p.requires_grad]


def _buffer(frames: int, batch_size: int, device: torch.device) -> TensorDictReplayBuffer:
    return TensorDictReplayBuffer(storage=LazyTensorStorage(frames, device=device), batch_size=batch_size)
