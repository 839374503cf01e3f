"""Peer comparison: rlgrasp's training against Stable-Baselines3, same env, settings and budget.

Both run one after the other on the same machine, on the same wall-clock budget.

    pip install -c constraints.txt -e ".[peer]"
    python benchmarks/bench_peer.py --minutes 5 --seed 0
    python benchmarks/bench_peer.py --minutes 5 --only sb3 -- env.control.mode=ee_delta
    python benchmarks/bench_peer.py --minutes 5 --experiment grasp_sac
    python benchmarks/bench_peer.py --algo tqc --minutes 60 -- total_frames=102400
    python benchmarks/bench_peer.py --algo tqc --env-id panda_gym:PandaPush-v3 --minutes 60

rlgrasp runs as ``scripts/train.py experiment=<experiment>`` and is read back from its TensorBoard.
The SB3 algorithm follows the experiment's ``algo.name``: PPO for ``ppo``, SAC for ``sac``,
sb3-contrib's TQC for ``tqc``; ``--algo`` names it and, without ``--experiment``, runs its experiment
(``tqc``: ``panda_pick_place_tqc_her``, panda-gym's PandaPickAndPlace-v3 on RL Zoo's settings;
``--env-id`` another env=gym id). With ``algo.her`` SB3 relabels with its ``HerReplayBuffer`` on the
same goal env read as its Dict (``her_kwargs``). It runs
over a ``SubprocVecEnv`` of the same env (SB3's layout: one process per env) behind ``VecNormalize``
on observations only (rlgrasp normalizes observations, not rewards), with the keywords
``sb3_kwargs`` maps from the same composed config; ``unmatched`` names what SB3 cannot set alike.
SB3's periodic evaluation is rlgrasp's own ``Evaluator`` (same episodes, seeds and deterministic
actions) run inside SB3's ``learn`` after an update, so it costs SB3's clock what it costs
rlgrasp's. Each side runs in its own process and its minutes count from that process's launch, so
start-up is charged to both alike.

Printed for each side: eval success against minutes, ``SPS`` (rlgrasp's console figure: frames/s
from the end of the first update on, evaluations included) and frames/s from launch; both curves
side by side at the frames they evaluated at; then a table with the ratios rlgrasp/SB3. ``--record
PAGE/ID`` writes the ratios into that row of docs/benchmarks/results.json and its page's table
(benchmarks/results_file.py), met when the ratio
``--target-on`` names reaches ``--target`` (SB3's time to the first 0.9: at most ``--target``):

    python benchmarks/bench_peer.py --minutes 5 --seed 0 --record peer/ppo-fps --target 2.5

Module-level imports stay light (SB3's aside, which they load
anyway): SB3's spawned env workers run this file's top level again.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import math
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout, uninstalled
sys.path.insert(0, str(ROOT / "benchmarks"))  # bench_learning, also when this file is loaded by path

INSTALL_HINT = 'Stable-Baselines3 is not installed: pip install -c constraints.txt -e ".[peer]"'

try:
    from stable_baselines3.common.callbacks import BaseCallback
except ImportError:  # the `peer` extra is optional; only the SB3 side needs it, and checks first
    BaseCallback = object  # type: ignore[assignment,misc]


# --- the mapping --------------------------------------------------------------------------------
@dataclass(frozen=True)
class LinearLR:
    """rlgrasp's ``lr_at`` as an SB3 schedule: SB3 passes the fraction of ``total_timesteps`` left,
    which is rlgrasp's ``1 - frames / total_frames`` when both learn for ``total_frames``."""

    lr: float
    min_frac: float = 0.0
    anneal: bool = True

    def __call__(self, progress_remaining: float) -> float:
        return self.lr * max(self.min_frac, progress_remaining) if self.anneal else self.lr


def n_envs(cfg: Any) -> int:
    """SB3's env count: rlgrasp's workers x envs per worker (same frames per batch)."""
    from rlgrasp.train.collection.collectors import collector_backend

    return collector_backend(cfg.collector).frames_per_batch // cfg.collector.steps_per_env


#: The SB3 class each rlgrasp algorithm is compared with (TQC's is sb3-contrib's), and the experiment
#: ``--algo`` runs when no ``--experiment`` is given.
SB3_CLASSES = {"ppo": "PPO", "sac": "SAC", "tqc": "TQC"}
EXPERIMENTS = {"ppo": "grasp_ppo", "sac": "grasp_sac", "tqc": "panda_pick_place_tqc_her"}
CONTRIB_HINT = 'sb3-contrib is not installed (its TQC is the peer of algo=tqc): pip install -e ".[peer]"'


def sb3_algo(cfg: Any) -> str:
    """The SB3 class the config's algorithm is compared with (the peer must learn the same way)."""
    if cfg.algo.name not in SB3_CLASSES:
        raise ValueError(
            f"algo.name={cfg.algo.name!r}: the SB3 side runs {', '.join(SB3_CLASSES.values())} only"
        )
    return SB3_CLASSES[cfg.algo.name]


def sb3_class(cfg: Any) -> Any:
    """The SB3 (or sb3-contrib) class ``sb3_algo`` names."""
    import stable_baselines3

    name = sb3_algo(cfg)
    if name == "TQC":
        import sb3_contrib

        return sb3_contrib.TQC
    return getattr(stable_baselines3, name)


def off_policy(cfg: Any) -> bool:
    return sb3_algo(cfg) in ("SAC", "TQC")


def sb3_kwargs(cfg: Any) -> dict[str, Any]:
    """SB3 keywords for a composed rlgrasp training config (env, seed and device aside), for the
    class ``sb3_algo`` names; a ``ValueError`` for a config SB3 cannot run."""
    if not off_policy(cfg):
        return ppo_kwargs(cfg)
    kwargs = sac_kwargs(cfg)
    if sb3_algo(cfg) == "TQC":
        kwargs["top_quantiles_to_drop_per_net"] = cfg.algo.loss.top_quantiles_to_drop_per_net
        kwargs["policy_kwargs"]["n_quantiles"] = cfg.algo.loss.n_quantiles
    return {**kwargs, **her_kwargs(cfg)}


def ppo_kwargs(cfg: Any) -> dict[str, Any]:
    """SB3 ``PPO`` keywords for a composed rlgrasp PPO config."""
    from rlgrasp.models.mlp import ACTIVATIONS

    loss, o, sched, m = cfg.algo.loss, cfg.algo.optim, cfg.algo.schedule, cfg.model
    if loss.loss_critic_type != "l2":
        raise ValueError(f"algo.loss.loss_critic_type={loss.loss_critic_type!r}: SB3's value loss is l2 only")
    return {
        "n_steps": cfg.collector.steps_per_env,
        "batch_size": o.minibatch_size,
        "n_epochs": o.epochs,
        "learning_rate": LinearLR(o.lr, sched.min_lr_frac, sched.anneal_lr),
        "gamma": loss.gamma,
        "gae_lambda": loss.gae_lambda,
        "clip_range": loss.clip_epsilon,
        "ent_coef": loss.entropy_coeff,
        "vf_coef": loss.critic_coeff,
        "max_grad_norm": o.max_grad_norm,
        "normalize_advantage": loss.normalize_advantage,
        # SB3 stops an update once its KL estimate exceeds 1.5 x target_kl, rlgrasp at target_kl.
        "target_kl": None if sched.target_kl is None else sched.target_kl / 1.5,
        "policy_kwargs": {
            "net_arch": {"pi": list(m.hidden_sizes), "vf": list(m.hidden_sizes)},
            "activation_fn": ACTIVATIONS[m.activation],
            "log_std_init": m.init_log_std,
            "ortho_init": True,  # rlgrasp's init too: gain sqrt(2), 0.01 on the policy head, 1 on the value
            "optimizer_kwargs": {"eps": o.adam_eps},
        },
    }


def gradient_steps(cfg: Any) -> int:
    """SB3's gradient steps per rollout for rlgrasp's ``utd_ratio``: a rollout is one batch
    (``steps_per_env`` steps of every env), so ``utd_ratio`` x its frames, rounded (SB3 takes a
    whole number; rlgrasp carries the fraction over to the next batch)."""
    return round(cfg.algo.optim.utd_ratio * n_envs(cfg) * cfg.collector.steps_per_env)


def sac_kwargs(cfg: Any) -> dict[str, Any]:
    """SB3 ``SAC`` keywords for a composed rlgrasp SAC config: one rollout per rlgrasp batch, the
    same update-to-data ratio, replay, temperature and networks."""
    from rlgrasp.models.mlp import ACTIVATIONS

    a, m = cfg.algo, cfg.model
    if a.get("demos"):
        raise ValueError(f"algo.demos={a.demos}: SB3's SAC replays no demonstrations")
    steps = gradient_steps(cfg)
    if steps < 1:
        frames = n_envs(cfg) * cfg.collector.steps_per_env
        raise ValueError(
            f"algo.optim.utd_ratio={a.optim.utd_ratio} x {frames} frames a batch rounds to 0 gradient "
            "steps: SB3 would never train"
        )
    return {
        "train_freq": (cfg.collector.steps_per_env, "step"),  # each of the n_envs envs steps this often
        "gradient_steps": steps,
        "batch_size": a.optim.batch_size,
        "buffer_size": a.replay.buffer_frames,
        "learning_starts": a.replay.learning_starts,
        "learning_rate": a.optim.actor_lr,  # SB3's one rate for actor, critics and temperature
        "gamma": a.loss.gamma,
        "tau": a.loss.tau,
        "target_update_interval": 1,  # rlgrasp soft-updates the target critics after every step
        "ent_coef": f"auto_{a.loss.alpha_init}",  # learned, starting at alpha_init
        "target_entropy": "auto"
        if a.loss.target_entropy is None
        else a.loss.target_entropy,  # auto: -(action size)
        "policy_kwargs": {
            "net_arch": {"pi": list(m.hidden_sizes), "qf": list(a.critic.hidden_sizes)},
            "activation_fn": ACTIVATIONS[m.activation],
            "n_critics": a.loss.num_critics,
        },
    }


def her_on(cfg: Any) -> bool:
    """Whether the config relabels with HER (``algo.her.enabled``; PPO has no such key)."""
    her = cfg.algo.get("her")
    return bool(her is not None and her.enabled)


def her_kwargs(cfg: Any) -> dict[str, Any]:
    """SB3's ``HerReplayBuffer`` as rlgrasp's HER, on the same goal env read as its Dict (``env=gym``,
    ``env.observation=dict``): ``relabel_ratio`` r as ``n_sampled_goal`` r / (1 - r) (0.8: 4), the same
    strategy. SB3 draws goals only from finished episodes and refuses to sample before one has ended,
    so it starts training once every env has finished one (``her_learning_starts``)."""
    if not her_on(cfg):
        return {}
    from stable_baselines3 import HerReplayBuffer

    from rlgrasp.envs.gym_env import TARGET

    h = cfg.algo.her
    if cfg.env.get("_target_") != TARGET:
        raise ValueError(
            "algo.her.enabled=true: the SB3 side relabels another package's goal env (env=gym, read as "
            "its Dict); rlgrasp's own tasks keep their goals in the flat state"
        )
    if not 0 < h.relabel_ratio < 1:
        raise ValueError(f"algo.her.relabel_ratio={h.relabel_ratio}: SB3 relabels a share in (0, 1)")
    return {
        "replay_buffer_class": HerReplayBuffer,
        "replay_buffer_kwargs": {
            "n_sampled_goal": n_sampled_goal(h.relabel_ratio),
            "goal_selection_strategy": str(h.strategy),
        },
        "learning_starts": max(cfg.algo.replay.learning_starts, her_learning_starts(cfg)),
    }


def n_sampled_goal(ratio: float) -> int:
    """SB3's ``n_sampled_goal`` nearest rlgrasp's ``relabel_ratio`` (SB3 relabels k / (k + 1))."""
    return max(1, round(ratio / (1 - ratio)))


def her_learning_starts(cfg: Any) -> int:
    """Frames after which every env of the SB3 side has finished an episode (its envs step together)."""
    from rlgrasp.envs.factory import episode_steps

    return n_envs(cfg) * episode_steps(cfg.env)


def sb3_env_cfg(cfg: Any) -> Any:
    """The env node the SB3 side trains on: the run's, read as its Dict when HER relabels it (SB3's
    ``HerReplayBuffer`` takes the goals from their keys)."""
    from omegaconf import OmegaConf

    env = OmegaConf.to_container(cfg.env, resolve=True)
    return {**env, "observation": "dict"} if her_on(cfg) else env


def vecnorm_kwargs(cfg: Any) -> dict[str, Any]:
    """``VecNormalize`` as rlgrasp's ``RunningNorm``: observations only, clipped, eps 1e-8."""
    return {
        "norm_obs": bool(cfg.model.obs_norm),
        "norm_reward": False,
        "clip_obs": cfg.model.obs_clip,
        "epsilon": 1e-8,
    }


def unmatched(cfg: Any) -> list[str]:
    """What the SB3 side cannot set like rlgrasp, for this config (printed with the results)."""
    c = cfg.collector
    layout = (
        f"layout: {n_envs(cfg)} env processes (SubprocVecEnv steps one env per process); rlgrasp "
        f"{c.num_workers} workers x {c.envs_per_worker} envs"
    )
    if not off_policy(cfg):
        return [layout, *ppo_unmatched(cfg)]
    return [layout, *sac_unmatched(cfg), *her_unmatched(cfg)]


def ppo_unmatched(cfg: Any) -> list[str]:
    """PPO's differences: the std floor, the KL stop, the policy's squashing, the advantages."""
    notes = [
        f"std floor model.min_std={cfg.model.min_std}: SB3 has none",
        "target_kl: SB3 estimates KL as mean((r - 1) - log r) and stops before the step, rlgrasp as "
        "mean(-log r) and after it",
        "observation statistics: VecNormalize updates them every step, rlgrasp after each update",
    ]
    if cfg.model.get("distribution", "tanh_normal") == "tanh_normal":
        notes.append(
            "policy: SB3 samples a Gaussian and clips actions to the bounds; rlgrasp's TanhNormal "
            "squashes them (SB3 squashes only with gSDE; model.distribution=normal is SB3's)"
        )
    if cfg.algo.loss.gae_every_epoch:
        notes.append("algo.loss.gae_every_epoch=true: SB3 computes advantages once per rollout")
    desired_kl = cfg.algo.schedule.desired_kl
    if desired_kl is not None:
        notes.append(
            f"algo.schedule.desired_kl={desired_kl}: SB3 has no KL-adaptive learning rate; it gets "
            "algo.optim.lr on the linear schedule"
        )
    return notes


def her_unmatched(cfg: Any) -> list[str]:
    """HER's differences: which episodes give goals, when training starts, the share relabelled."""
    if not her_on(cfg):
        return []
    h, starts = cfg.algo.her, cfg.algo.replay.learning_starts
    notes = [
        "HER: SB3's HerReplayBuffer draws goals only from finished episodes; rlgrasp from the steps "
        "stored so far of the row's own episode, finished or not"
    ]
    if her_learning_starts(cfg) > starts:
        notes.append(
            f"algo.replay.learning_starts={starts}: SB3 cannot sample before an episode has ended, so it "
            f"starts after {her_learning_starts(cfg)} frames (every env's first episode)"
        )
    k = n_sampled_goal(h.relabel_ratio)
    if abs(k / (k + 1) - h.relabel_ratio) > 1e-9:
        notes.append(
            f"algo.her.relabel_ratio={h.relabel_ratio}: SB3 relabels n_sampled_goal / (n_sampled_goal + 1); "
            f"n_sampled_goal={k} relabels {k / (k + 1):.3f}"
        )
    if cfg.model.obs_norm:
        notes.append(
            "VecNormalize normalizes each key of the Dict, the goals included; rlgrasp the flat vector"
        )
    return notes


def sac_unmatched(cfg: Any) -> list[str]:
    """SAC's differences: the std, the rates, the critics' make-up, the warm-up, the batch timing."""
    from rlgrasp.train.collection.collectors import collector_backend

    a, m, name = cfg.algo, cfg.model, sb3_algo(cfg)
    notes = [
        f"std: rlgrasp's actor has a state-independent std (a learned vector from model.init_log_std="
        f"{m.init_log_std}, floor model.min_std={m.min_std}); SB3's {name} a state-dependent one (a linear "
        "head, log-std clipped to [-20, 2]; its log_std_init applies only with gSDE)",
        f"init: rlgrasp's actor is orthogonal (gain sqrt(2), 0.01 on the head); SB3's {name} "
        "PyTorch's default",
        "warm-up: SB3 acts uniformly at random until algo.replay.learning_starts frames and trains from "
        "the first batch past them; rlgrasp acts with its initial policy and trains from the batch that "
        "reaches them",
        "observation statistics: VecNormalize updates them every step, rlgrasp once a batch",
    ]
    if not a.optim.critic_lr == a.optim.alpha_lr == a.optim.actor_lr:
        notes.append(
            f"learning rates: SB3 has one for actor, critics and temperature (algo.optim.actor_lr="
            f"{a.optim.actor_lr}); rlgrasp's critics use algo.optim.critic_lr={a.optim.critic_lr}, its "
            f"temperature algo.optim.alpha_lr={a.optim.alpha_lr}"
        )
    if a.critic.layer_norm:
        notes.append(f"algo.critic.layer_norm=true: SB3's {name} critics have no LayerNorm")
    if a.critic.activation != m.activation:
        notes.append(
            f"activation: SB3's {name} has one for actor and critics (model.activation="
            f"{m.activation}); rlgrasp's critics use algo.critic.activation={a.critic.activation}"
        )
    if a.optim.actor_every != 1:
        notes.append(
            f"algo.optim.actor_every={a.optim.actor_every}: SB3's {name} steps the actor and temperature "
            "every gradient step"
        )
    per_batch = a.optim.utd_ratio * n_envs(cfg) * cfg.collector.steps_per_env
    if per_batch != gradient_steps(cfg):
        notes.append(
            f"algo.optim.utd_ratio={a.optim.utd_ratio}: {per_batch:g} gradient steps a batch, SB3 takes "
            f"{gradient_steps(cfg)} (a whole number; rlgrasp carries the fraction over)"
        )
    if collector_backend(cfg.collector).collects_ahead:
        notes.append(
            "collector.overlap=true: rlgrasp's workers collect the next batch during the update "
            "(with the policy one update behind); SB3 steps its envs only between updates"
        )
    if m.get("distribution", "tanh_normal") == "normal":
        notes.append(
            f"model.distribution=normal: rlgrasp's actor is an unsquashed Gaussian, SB3's {name} "
            "squashes with tanh"
        )
    return notes


# --- the SB3 side (its own process) ---------------------------------------------------------------
def eval_policy(model: Any, vecnorm: Any, slices: dict[str, slice] | None = None) -> Any:
    """SB3's deterministic action (PPO: the mean, clipped to the bounds; SAC and TQC: the mean, squashed
    into them) on VecNormalize's view of the observation, as the TensorDict module rlgrasp's
    ``Evaluator`` rolls out. ``slices``: a goal env's keys in rlgrasp's flat observation, which SB3's
    HER learner reads as the env's Dict (``rlgrasp.envs.gym_env``: the same values, split)."""
    import torch  # imports inside functions: SB3's env workers re-run this file's top level
    from tensordict.nn import TensorDictModule

    def act(obs: torch.Tensor) -> torch.Tensor:
        seen = obs.numpy()
        if slices is not None:
            seen = {key: seen[..., where] for key, where in slices.items()}
        action, _ = model.predict(vecnorm.normalize_obs(seen), deterministic=True)
        return torch.as_tensor(action, dtype=torch.float32)

    return TensorDictModule(act, in_keys=["observation"], out_keys=["action"])


class PeriodicEval(BaseCallback):
    """rlgrasp's loop order inside SB3's ``learn``: after each update the SPS, then an evaluation
    when one is due, then the budget check before the next rollout (SB3 stops at its first step).

    Both of SB3's loops call ``on_rollout_start`` before each rollout, after the previous update:
    PPO's rollout is ``n_steps`` steps, SAC's ``train_freq`` steps, of every env. ``num_timesteps``
    counts the steps of all envs, rlgrasp's frames."""

    def __init__(
        self,
        cfg: Any,
        evaluator: Any,
        vecnorm: Any,
        start: float,
        budget_s: float,
        slices: dict[str, slice] | None = None,
    ) -> None:
        # the schedule and SPS training itself uses (imported here: see the module docstring)
        from rlgrasp.train.tracking.metrics import Due, Throughput

        super().__init__()
        self.cfg, self.evaluator, self.vecnorm, self.slices = cfg, evaluator, vecnorm, slices
        self.start, self.budget_s = start, budget_s
        self.due, self.throughput = Due(cfg.eval.interval_frames, 0), Throughput()
        self.frames, self.over, self.batch_t0 = 0, False, time.perf_counter()
        self.evals: list[tuple[float, int, float, int]] = []  # (unix time, frames, success, episodes)
        self.sps: list[tuple[float, int, float]] = []  # (unix time, frames, SPS) after each update

    def _on_rollout_start(self) -> None:
        if self.num_timesteps > self.frames:
            self._after_update()
        self.over = time.monotonic() - self.start >= self.budget_s
        self.batch_t0 = time.perf_counter()

    def _on_step(self) -> bool:
        return not self.over

    def _on_training_end(self) -> None:
        if not self.over and self.num_timesteps > self.frames:  # ended on total_frames
            self._after_update()

    def _after_update(self) -> None:
        new, self.frames = self.num_timesteps - self.frames, self.num_timesteps
        sps = self.throughput(new, self.batch_t0)
        self.sps.append((time.time(), self.frames, sps))
        if self.due(self.frames) and self.frames < self.cfg.total_frames:  # the last one is the final
            self.evaluate(self.cfg.eval.episodes)

    def evaluate(self, episodes: int) -> None:
        result = self.evaluator.run(eval_policy(self.model, self.vecnorm, self.slices), episodes)
        success = result.get("success_rate", math.nan)
        self.evals.append((time.time(), self.frames, success, episodes))
        sps = self.sps[-1][2] if self.sps else math.nan
        print(
            f"{self.frames:>9,} frames  SPS {sps:,.0f}  eval success {success:.3f} ({episodes} episodes)",
            flush=True,
        )


def goal_slices(make_env: Any) -> dict[str, slice]:
    """Where each of a goal env's Dict keys lies in rlgrasp's flat observation of it."""
    env = make_env()
    try:
        return dict(env.unwrapped.obs_slices)
    finally:
        env.close()


def run_sb3(cfg: Any, out_json: Path) -> None:
    """Train SB3's PPO or SAC, or sb3-contrib's TQC (with HER where the config has it) on ``cfg`` until
    its frames or time budget run out, then the final evaluation, as ``Trainer.finish`` does; writes the
    curve to ``out_json``. The evaluation is rlgrasp's, on rlgrasp's flat env."""
    import torch  # imports inside functions: SB3's env workers re-run this file's top level
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from rlgrasp.envs.factory import env_factory
    from rlgrasp.train.collection.collect import worker_seed
    from rlgrasp.train.evaluation.evaluate import periodic_evaluator
    from rlgrasp.train.loop import resolve_device

    torch.set_num_threads(cfg.collector.torch_threads)  # rlgrasp's learner threads (Trainer sets them)
    start = time.monotonic()  # the budget includes the workers' start-up, as in Trainer.run
    make_env = env_factory(cfg.env)
    train_env = env_factory(sb3_env_cfg(cfg))
    venv = VecNormalize(SubprocVecEnv([train_env] * n_envs(cfg), start_method="spawn"), **vecnorm_kwargs(cfg))
    evaluator = periodic_evaluator(make_env, cfg)
    slices = goal_slices(make_env) if her_on(cfg) else None
    try:
        model = sb3_class(cfg)(
            "MultiInputPolicy" if her_on(cfg) else "MlpPolicy",
            venv,
            seed=cfg.seed,
            device=str(resolve_device(cfg.device)),
            verbose=0,
            **sb3_kwargs(cfg),
        )
        venv.seed(worker_seed(cfg.seed, 0))  # env k seeded worker_seed + k (rlgrasp: per worker)
        budget_s = cfg.time_budget_min * 60 if cfg.time_budget_min else math.inf
        callback = PeriodicEval(cfg, evaluator, venv, start, budget_s, slices)
        model.learn(total_timesteps=cfg.total_frames, callback=callback)
        final = cfg.eval.final_episodes or cfg.eval.episodes
        last = callback.evals[-1] if callback.evals else None
        if last is None or last[1] != callback.frames or final > cfg.eval.episodes:
            callback.evaluate(final)
    finally:
        evaluator.close()
        venv.close()
    out_json.write_text(json.dumps({"evals": callback.evals, "sps": callback.sps}))


def sb3_child(args: argparse.Namespace) -> None:
    """``--sb3-child``: compose the config as training would and run the SB3 side in this process."""
    from rlgrasp.compose import compose_train
    from rlgrasp.train.validate import validate_train

    run_dir = args.out / f"sb3_seed{args.seed}"
    cfg = compose_train(
        [
            f"experiment={args.experiment}",
            f"seed={args.seed}",
            f"time_budget_min={args.minutes}",
            f"paths.output_dir={run_dir}",
            *args.overrides,
        ]
    )
    validate_train(cfg)
    print(
        f"SB3 {sb3_algo(cfg)}: {n_envs(cfg)} envs (SubprocVecEnv), VecNormalize {vecnorm_kwargs(cfg)}",
        flush=True,
    )
    print(f"{sb3_algo(cfg)} keywords: {sb3_kwargs(cfg)}", flush=True)
    run_sb3(cfg, args.out / f"sb3_seed{args.seed}.json")


# --- the parent: run both, read them, compare ----------------------------------------------------
def rlgrasp_side(args: argparse.Namespace) -> dict[str, Any]:
    """``scripts/train.py`` (through bench_learning), read back from its TensorBoard."""
    import bench_learning
    from omegaconf import OmegaConf

    shutil.rmtree(args.out / f"rlgrasp_seed{args.seed}", ignore_errors=True)  # old events would mix in
    run = bench_learning.run_seed(
        args.out, "rlgrasp", args.seed, args.minutes, args.experiment, args.overrides
    )
    run_dir, start = run["run_dir"], run["start"]
    periodic = int(OmegaConf.load(run_dir / ".hydra" / "config.yaml").eval.episodes)
    curve = bench_learning.eval_curve(run_dir, start)
    evals = [(m, f, v, periodic) for m, f, v in curve[:-1]]
    evals += [(m, f, v, bench_learning.final_episodes(run_dir)) for m, f, v in curve[-1:]]
    sps = bench_learning.scalar_curve(run_dir, start, "charts/SPS")
    return {"evals": evals, "sps": sps, "wall_min": run["wall_s"] / 60}


def sb3_side(args: argparse.Namespace) -> dict[str, Any]:
    """This script again with ``--sb3-child``, in its own process like ``scripts/train.py``."""
    out_json = args.out / f"sb3_seed{args.seed}.json"
    out_json.unlink(missing_ok=True)
    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--sb3-child",
        "--seed",
        str(args.seed),
        "--minutes",
        str(args.minutes),
        "--experiment",
        args.experiment,
        "--out",
        str(args.out),
        "--",
        *args.overrides,
    ]
    print("$", " ".join(cmd[1:]), flush=True)
    start = time.time()
    with open(args.out / f"sb3_seed{args.seed}.log", "w") as log:
        code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
    if code != 0:
        raise SystemExit(f"the SB3 run failed (exit {code}); see {log.name}")
    wall_min = (time.time() - start) / 60
    data = json.loads(out_json.read_text())
    evals = [((t - start) / 60, f, v, n) for t, f, v, n in data["evals"]]
    sps = [((t - start) / 60, f, v) for t, f, v in data["sps"]]
    return {"evals": evals, "sps": sps, "wall_min": wall_min}


Curve = list[tuple[float, int, float, int]]  # (minutes from launch, frames, eval success, episodes)


def summary(evals: Curve, sps: list[tuple[float, int, float]]) -> dict[str, Any]:
    """Final success, SPS and frames/s from launch of one side's curves (minutes from its launch)."""
    from rlgrasp.stats import wilson_interval

    minutes, frames, last_sps = sps[-1] if sps else (math.nan, 0, math.nan)
    _, _, success, episodes = evals[-1] if evals else (math.nan, 0, math.nan, 0)
    low, high = wilson_interval(round(success * episodes), episodes) if episodes else (math.nan, math.nan)
    first_90 = next((m for m, _, v, _ in evals if v >= 0.9 - 1e-6), None)
    return {
        "frames": frames,
        "sps": last_sps,
        "launch_fps": frames / max(minutes * 60, 1e-9),
        "success": success,
        "episodes": episodes,
        "ci": f"[{low:.2f}, {high:.2f}]",
        "first_90": "-" if first_90 is None else f"{first_90:.1f} min",
        "first_90_min": first_90,
    }


def print_curves(results: dict[str, dict[str, Any]], args: argparse.Namespace) -> Path:
    """Each side's eval success against minutes, printed and written to one CSV."""
    names = {
        "rlgrasp": f"rlgrasp (scripts/train.py experiment={args.experiment})",
        "sb3": f"{args.sb3_name} (SubprocVecEnv + VecNormalize)",
    }
    rows = [("side", "seed", "minutes", "frames", "eval_success_rate", "episodes")]
    for side, r in results.items():
        print(f"\n{names[side]}, seed {args.seed}: eval success against minutes from launch")
        print(f"{'minutes':>8}{'frames':>10}{'success':>9}{'episodes':>9}")
        for minutes, frames, success, episodes in r["evals"]:
            print(f"{minutes:>8.2f}{frames:>10,}{success:>9.3f}{episodes:>9}")
            rows.append((side, args.seed, round(minutes, 3), frames, success, episodes))
    csv_path = args.out / f"peer_seed{args.seed}.csv"
    with open(csv_path, "w", newline="") as f:
        csv.writer(f).writerows(rows)
    if len(results) == 2:
        print_by_frames(results, args.seed)
    return csv_path


def by_frames(results: dict[str, dict[str, Any]]) -> list[tuple[int, float | None, float | None]]:
    """Both sides' eval success at each frame count either evaluated at (None where one did not): both
    evaluate every ``eval.interval_frames`` on batches of one size, so the counts are the same."""
    seen = {side: {frames: success for _, frames, success, _ in r["evals"]} for side, r in results.items()}
    frames = sorted(set(seen["rlgrasp"]) | set(seen["sb3"]))
    return [(f, seen["rlgrasp"].get(f), seen["sb3"].get(f)) for f in frames]


def print_by_frames(results: dict[str, dict[str, Any]], seed: int) -> None:
    """The two learning curves side by side, by frames."""
    print(f"\nseed {seed}: eval success at the same frames")
    print(f"{'frames':>10}{'rlgrasp':>9}{'sb3':>9}")
    for frames, ours, theirs in by_frames(results):
        cells = ["-" if v is None or math.isnan(v) else f"{v:.3f}" for v in (ours, theirs)]
        print(f"{frames:>10,}{cells[0]:>9}{cells[1]:>9}")


def report(results: dict[str, dict[str, Any]], args: argparse.Namespace) -> None:
    """The curves, then the comparison table with the ratios rlgrasp/SB3."""
    csv_path = print_curves(results, args)
    sums = {side: summary(r["evals"], r["sps"]) for side, r in results.items()}
    print(
        f"\n{args.minutes} min budget each, seed {args.seed}, one after the other. SPS: frames/s from "
        "the end of the first update on, evaluations included (rlgrasp's console figure)"
    )
    print(
        f"{'':<12}{'frames':>10}{'SPS':>8}{'frames/s from launch':>22}{'final success':>15}"
        f"{'episodes':>9}{'95% Wilson':>14}{'first >= 0.9':>14}{'wall min':>10}"
    )
    for side, s in sums.items():
        print(
            f"{side:<12}{s['frames']:>10,}{s['sps']:>8,.0f}{s['launch_fps']:>22,.0f}{s['success']:>15.3f}"
            f"{s['episodes']:>9}{s['ci']:>14}{s['first_90']:>14}{results[side]['wall_min']:>10.1f}"
        )
    if len(sums) == 2:
        a, b = sums["rlgrasp"], sums["sb3"]
        print(
            f"{'rlgrasp/sb3':<12}{ratio(a['frames'], b['frames']):>10}{ratio(a['sps'], b['sps']):>8}"
            f"{ratio(a['launch_fps'], b['launch_fps']):>22}{ratio(a['success'], b['success']):>15}"
        )
    if "sb3" in results:
        print("\nNot matched on the SB3 side:\n  " + "\n  ".join(results["sb3"]["unmatched"]))
    print(f"\nwrote {csv_path}; logs in {args.out}")
    if getattr(args, "record", None):
        import results_file

        met = record_met(sums["rlgrasp"], sums["sb3"], args.target_on, args.target)
        results_file.record(
            *args.record, record_text(sums["rlgrasp"], sums["sb3"], args.seed), met, load=args.record_load
        )


def record_text(a: dict[str, Any], b: dict[str, Any], seed: int) -> str:
    """The results table's ``measured`` cell from both sides' summaries (rlgrasp ``a``, SB3 ``b``):
    the frames/s ratios, the time to the first 0.9 as a share of SB3's, the two final successes."""
    if a["first_90_min"] is not None and b["first_90_min"] is not None:
        first = f"first >= 0.9 in {ratio(a['first_90_min'], b['first_90_min'])} of SB3's time"
    else:
        first = f"first >= 0.9 at {a['first_90']} against SB3's {b['first_90']}"
    return (
        f"{ratio(a['sps'], b['sps'])}x SPS, {ratio(a['launch_fps'], b['launch_fps'])}x frames/s from "
        f"launch; {first}; final {a['success']:.2f} against SB3's {b['success']:.2f} (seed {seed})"
    )


RECORD_FIGURES = ("launch-fps", "sps", "first-0.9", "final")


def record_met(a: dict[str, Any], b: dict[str, Any], target_on: str, target: float | None) -> str:
    """The ``met`` cell: the ratio rlgrasp/SB3 of ``target_on`` against ``target`` (at least it; for
    the time to the first 0.9, at most it: less time is better); "see page" without a target."""
    if target is None:
        return "see page"
    keys = {"launch-fps": "launch_fps", "sps": "sps", "first-0.9": "first_90_min", "final": "success"}
    key = keys[target_on]
    if a[key] is None or math.isnan(a[key]):
        return "missed"  # rlgrasp never reached 0.9, or has no figure
    if b[key] is None or math.isnan(b[key]) or not b[key]:
        return "met" if target_on == "first-0.9" else "see page"  # SB3 never reached 0.9
    value = a[key] / b[key]
    return "met" if (value <= target if target_on == "first-0.9" else value >= target - 1e-9) else "missed"


def ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}" if b and not (math.isnan(a) or math.isnan(b)) else "-"


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=5.0, help="wall-clock budget of each side")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", choices=["rlgrasp", "sb3"], help="run one side only")
    parser.add_argument(
        "--algo",
        choices=sorted(EXPERIMENTS),
        help="the algorithm compared (its SB3 peer: PPO, SAC, or sb3-contrib's TQC); without "
        "--experiment, its experiment: " + ", ".join(f"{k} {v}" for k, v in EXPERIMENTS.items()),
    )
    parser.add_argument("--experiment", help="the experiment both sides run (default: --algo's; grasp_ppo)")
    parser.add_argument(
        "--env-id", help="env.id for both sides, with an env=gym experiment (e.g. panda_gym:PandaPush-v3)"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_peer")
    parser.add_argument("--sb3-child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("overrides", nargs="*", help="training overrides for both sides, after --")
    import results_file  # here, not at the top: SB3's env workers re-run the top level

    results_file.add_options(parser)
    parser.add_argument("--target", type=float, help="with --record: the ratio rlgrasp/SB3 to reach")
    parser.add_argument(
        "--target-on",
        choices=RECORD_FIGURES,
        default="launch-fps",
        help="with --target: which ratio (first-0.9: rlgrasp's share of SB3's time)",
    )
    args = parser.parse_args()
    if args.record and args.only:
        parser.error("--record compares both sides: not with --only")
    args.experiment = args.experiment or EXPERIMENTS[args.algo or "ppo"]
    return args


def checked_config(args: argparse.Namespace, sides: list[str]) -> Any:
    """The experiment's config with the command line's overrides and ``--env-id`` (added to them), refused
    in one line (a SystemExit) before either side runs: another algorithm than ``--algo``, ``--env-id``
    without ``env=gym``, a missing sb3-contrib for TQC."""
    from rlgrasp.compose import compose_train
    from rlgrasp.envs.gym_env import TARGET

    cfg = compose_train([f"experiment={args.experiment}", f"seed={args.seed}", *args.overrides])
    if args.algo and cfg.algo.name != args.algo:
        raise SystemExit(f"--algo {args.algo}: experiment={args.experiment} trains algo={cfg.algo.name}")
    if args.env_id and cfg.env.get("_target_") != TARGET:
        raise SystemExit(f"--env-id {args.env_id}: experiment={args.experiment} is not an env=gym experiment")
    if args.env_id:  # an override of both sides from here on (the SB3 child gets it after --)
        args.overrides = [*args.overrides, f"env.id={args.env_id}"]
        cfg = compose_train([f"experiment={args.experiment}", f"seed={args.seed}", *args.overrides])
    if "sb3" in sides and cfg.algo.name == "tqc" and importlib.util.find_spec("sb3_contrib") is None:
        raise SystemExit(CONTRIB_HINT)
    return cfg


def sb3_name(cfg: Any) -> str:
    """How the report names the SB3 side."""
    name = "sb3-contrib TQC" if sb3_algo(cfg) == "TQC" else f"Stable-Baselines3 {sb3_algo(cfg)}"
    return name + (" + HerReplayBuffer" if her_on(cfg) else "")


def main() -> None:
    args = parse_args()
    args.out = args.out.resolve()
    args.out.mkdir(parents=True, exist_ok=True)
    sides = [args.only] if args.only else ["rlgrasp", "sb3"]
    if "sb3" in sides and importlib.util.find_spec("stable_baselines3") is None:
        raise SystemExit(INSTALL_HINT)
    if args.sb3_child:
        sb3_child(args)
        return
    cfg = checked_config(args, sides)
    args.sb3_name, notes = "", []
    if "sb3" in sides:  # refused before either side runs, not after rlgrasp's minutes
        try:
            args.sb3_name, notes = sb3_name(cfg), unmatched(cfg)
            sb3_kwargs(cfg)
        except ValueError as exc:
            raise SystemExit(f"the SB3 side cannot run this config: {exc}") from None
    results = {}
    for side in sides:
        results[side] = rlgrasp_side(args) if side == "rlgrasp" else sb3_side(args)
    if "sb3" in results:
        results["sb3"]["unmatched"] = notes
    report(results, args)


if __name__ == "__main__":
    main()
