"""End-to-end runs of the training pipeline on small budgets (real env, process collector), the
promise that one seed gives one run on the machine it runs on, and a guard of what a seed decides
before any torch kernel runs: what a refactor must not change, on any CPU.

Nothing here pins a float that training computes: torch's kernels differ in the last bits between
CPUs (AVX2, AVX-512), and the physics amplifies those bits over a run.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from rlgrasp.envs.grasp_env import EnvConfig
from rlgrasp.policy_file import load_checkpoint, policy_from_checkpoint, read_checkpoint
from rlgrasp.train.loop import Trainer, TrainingError, train
from rlgrasp.train.parts import build_parts
from rlgrasp.utils import flatten
from tests.helpers import record_differences, run_record, tensorboard_scalars, train_twice

REQUIRED_TAGS = {
    "charts/episodic_return",
    "charts/episodic_length",
    "charts/success_rate",
    "charts/SPS",
    "charts/learning_rate",
    "losses/policy_loss",
    "losses/value_loss",
    "losses/entropy",
    "losses/approx_kl",
    "losses/clipfrac",
    "losses/explained_variance",
    "losses/grad_norm",
    "eval/mean_reward",
    "eval/success_rate",
    "time/collect_s",
    "time/train_s",
    # each of the task's reward terms, its mean episode sum (rlgrasp.envs.tasks.terms)
    "rewards/reach",
    "rewards/grasp",
    "rewards/lift",
    "rewards/success",
}


def test_smoke_end_to_end_then_resume(tmp_path: Path, train_cfg) -> None:
    run_dir = tmp_path / "run"
    success = train(train_cfg("experiment=smoke", run_dir=run_dir))
    assert isinstance(success, float) and 0.0 <= success <= 1.0
    tags = set(tensorboard_scalars(run_dir).Tags()["scalars"])
    assert REQUIRED_TAGS <= tags, REQUIRED_TAGS - tags
    ckpts = run_dir / "checkpoints"
    assert (ckpts / "last.pt").is_file() and (ckpts / "best.pt").is_file()
    assert len(list(ckpts.glob("ckpt_*.pt"))) <= 2  # keep_last
    log_text = (run_dir / "train.log").read_text()
    assert log_text.count("frames") > 0
    # the final evaluation runs eval.final_episodes (8 in smoke), not 4
    assert re.search(r"final eval: success \d/8 \[95% Wilson", log_text), log_text[-800:]

    ckpt = load_checkpoint(run_dir)
    assert ckpt["frames"] == 2048
    assert {"actor", "ppo", "rng", "config", "versions", "spec"} <= set(ckpt)
    assert {"critic", "optimizer"} <= set(ckpt["ppo"])  # the algorithm's state under its name
    assert ckpt["config"]["env"]["_target_"] == "rlgrasp.envs.PandaGraspEnv"
    norm_count = [v for k, v in ckpt["actor"].items() if k.endswith("norm.count")]
    assert len(norm_count) == 1 and float(norm_count[0]) > 0
    policy = policy_from_checkpoint(ckpt)
    obs = torch.zeros(3, ckpt["spec"]["obs_dim"])
    a1 = policy(TensorDict({"observation": obs}, [3]))["action"]
    a2 = policy(TensorDict({"observation": obs}, [3]))["action"]
    assert a1.shape == (3, ckpt["spec"]["action_dim"])
    assert torch.equal(a1, a2)  # deterministic

    # resume: same run dir, frames and curves continue (one more 1,024-frame batch is enough to see it)
    train(train_cfg("experiment=smoke", f"resume={run_dir}", "total_frames=3072", run_dir=run_dir))
    assert load_checkpoint(run_dir)["frames"] == 3072
    steps = [e.step for e in tensorboard_scalars(run_dir).Scalars("losses/policy_loss")]
    assert steps == sorted(steps) and steps[-1] == 3072 and 2048 in steps


@pytest.mark.parametrize("collector", [pytest.param("process", marks=pytest.mark.full), "single"])
def test_crashing_env_stops_with_a_clear_error(tmp_path: Path, collector: str, train_cfg) -> None:
    cfg = train_cfg("experiment=smoke", f"collector={collector}", "total_frames=100000")
    cfg.env = OmegaConf.merge(
        OmegaConf.to_container(cfg.env), {"_target_": "tests.standins.crashing_grasp_env", "crash_after": 300}
    )
    with pytest.raises(TrainingError) as info:
        train(cfg)
    message = str(info.value)
    assert "worker 0 env" in message and "deliberate crash after 300 steps" in message, message
    assert (tmp_path / "checkpoints" / "last.pt").is_file()


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_stand_in_env_from_tests_reaches_spawned_workers(tmp_path: Path, train_cfg) -> None:
    """A `_target_` inside tests/ is importable in the collector's spawned workers too."""
    cfg = train_cfg("experiment=smoke", "collector.num_workers=1", "collector.envs_per_worker=2")
    cfg.env = {"_target_": "tests.standins.pendulum", "max_episode_steps": 20}
    parts = build_parts(cfg)
    assert parts.spec["obs_dim"] == 3 and parts.spec["action_dim"] == 1
    collector = parts.make_collector(0, str(tmp_path / "errors"))
    try:
        batch = next(iter(collector))
    finally:
        collector.shutdown()
    assert batch.numel() == parts.frames_per_batch == 512


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_process_workers_leave_the_learners_torch_threads_as_set(tmp_path: Path, train_cfg) -> None:
    """TorchRL's collector would give this process the cores left after one a worker (one, with two
    workers on two cores), and the learner would update on it whatever ``algo.learner_threads`` says."""
    cfg = train_cfg("experiment=smoke", "collector.num_workers=2", "collector.envs_per_worker=1")
    threads = torch.get_num_threads()
    torch.set_num_threads(3)
    try:
        collector = build_parts(cfg).make_collector(0, str(tmp_path / "errors"))
        try:
            next(iter(collector))
            assert torch.get_num_threads() == 3  # (TorchRL's shutdown sets them again, as it likes)
        finally:
            collector.shutdown()
    finally:
        torch.set_num_threads(threads)


# --- one seed, one run (on the machine the test runs on) -----------------------------------------
@pytest.mark.full  # two smoke runs on process workers
def test_a_seed_gives_one_run_on_this_machine(tmp_path: Path, train_cfg) -> None:
    """Twice the same seed on process workers that collect while the learner updates (four updates,
    each batch after the first one update late): the same curves, checkpoints, evaluation and weights,
    bit for bit. Not across machines: another CPU's kernels round differently."""
    overrides = ("collector.steps_per_env=128",)  # 512-frame batches: 4 updates in 2,048 frames
    cfg = train_cfg("experiment=smoke", *overrides)
    assert cfg.collector._target_ == "rlgrasp.train.collection.collectors.ProcessCollector"
    assert cfg.collector.num_workers == 2 and cfg.collector.overlap
    first, second = train_twice(train_cfg, tmp_path, *overrides)
    assert len(first["curves"]["losses/policy_loss"]) == 4 and len(first["checkpoints"]) >= 3
    assert {"eval/mean_reward", "losses/approx_kl", "charts/episodic_return"} <= set(first["curves"])
    assert record_differences(first, second) == []


@pytest.mark.slow
def test_evaluating_in_the_background_gives_the_same_run(tmp_path: Path, train_cfg) -> None:
    """``eval.background=true``: the same curves (``eval/*`` at the frames of the weights evaluated),
    checkpoints, final evaluation and weights as evaluating in the learner's process, and a ``best.pt``
    holding the weights that were evaluated; only when the results reach the learner differs."""
    overrides = ("collector.steps_per_env=128", "eval.interval_frames=512")  # 3 periodic evaluations
    records, best = [], []
    for background in ("false", "true"):
        run = tmp_path / background
        train(train_cfg("experiment=smoke", *overrides, f"eval.background={background}", run_dir=run))
        records.append(run_record(run))
        ckpt = read_checkpoint(run / "checkpoints" / "best.pt")
        weights = {k: v.numpy().tobytes() for k, v in ckpt["actor"].items()}
        best.append((ckpt["frames"], ckpt["last_eval"], ckpt["best_eval_success"], weights))
    in_learner, in_background = records
    assert [step for step, _ in in_learner["curves"]["eval/mean_reward"]] == [512, 1024, 1536, 2048]
    assert record_differences(in_learner, in_background) == []
    assert best[0][0] < 2048 and best[0] == best[1]  # a periodic evaluation's weights


@pytest.mark.full  # two runs on process workers
def test_the_seed_check_catches_an_unseeded_worker(tmp_path: Path, train_cfg) -> None:
    """The check above is not vacuous: workers that draw their torch seed from the OS (a forgotten
    worker seed) sample other actions each run, and the check names what moved."""
    first, second = train_twice(
        train_cfg,
        tmp_path,
        "collector.num_workers=1",
        "collector.steps_per_env=128",
        "total_frames=512",
        env_target="tests.standins.unseeded_worker_grasp_env",
    )
    differ = record_differences(first, second)
    assert "losses/policy_loss" in differ and any(name.endswith("weight") for name in differ), differ


# --- the refactor guard: what the seed decides before any torch kernel runs ----------------------
#: experiment=smoke composed, except ``env`` (its own guard below) and ``paths.output_dir``.
SMOKE_CONFIG = """
algo:
  _target_: rlgrasp.algos.ppo.PPO
  name: ppo
  loss: {gamma: 0.9, gae_lambda: 0.9, gae_every_epoch: true, clip_epsilon: 0.2, entropy_coeff: 0.0,
         critic_coeff: 0.5, loss_critic_type: l2, normalize_advantage: true}
  optim: {lr: 0.0003, adam_eps: 1.0e-05, max_grad_norm: 0.5, epochs: 2, minibatch_size: 256}
  schedule: {anneal_lr: true, min_lr_frac: 0.0, anneal_lr_frames: null, target_kl: 0.05, desired_kl: null,
             critic_warmup_frames: 0}
  demos: null
  pretrain: {epochs: 0, lr: 0.001, minibatch_size: 64, only: false}
  terms:
    imitation: {_target_: rlgrasp.demos.bc.Imitation, coeff: 0.1, decay: 0.95, minibatch_size: 256}
    teacher: {_target_: rlgrasp.vision.teacher_term.TeacherImitation, checkpoint: null, coeff: 1.0,
              decay: 1.0}
    rnd: {_target_: rlgrasp.algos.ppo.rnd.RND, coeff: 0.0, gamma: 0.99, features: 64, update_fraction: 0.25}
  init_from: null
model: {name: mlp, hidden_sizes: [64, 64], activation: tanh, init_log_std: -0.5, min_std: 0.05,
        obs_norm: true, obs_clip: 10.0, distribution: tanh_normal}
collector: {_target_: rlgrasp.train.collection.collectors.ProcessCollector, num_workers: 2,
            envs_per_worker: 2, steps_per_env: 256, torch_threads: 1, overlap: true, stagger_starts: false,
            worker_timeout_s: 600.0}
logger: {_target_: rlgrasp.train.tracking.logger.TensorBoardLogger, console_interval_s: 0.0}
eval: {interval_frames: 1024, episodes: 4, final_episodes: 8, num_envs: 4, seed_offset: 1000000,
       background: false, randomization: null}
checkpoint: {interval_frames: 1024, keep_last: 2}
paths: {root_dir: .}
experiment_name: smoke
seed: 0
device: auto
total_frames: 2048
time_budget_min: null
resume: null
"""
#: The env's spec under experiment=smoke (ee_delta control).
SMOKE_SPEC = {
    "obs_key": "observation",
    "obs_dim": 45,
    "action_dim": 4,
    "action_low": [-1.0] * 4,
    "action_high": [1.0] * 4,
    "reward_terms": ["reach", "grasp", "lift", "success"],
}
#: Each weight matrix after the seeded init: shape, L1 norm and its first three entries. The init is
#: orthogonal, from LAPACK's QR: another CPU's rounding moves these by ~1e-7, a seed change by ~1e-1.
SMOKE_INIT = {
    "actor:module.0.module.mlp.0.weight": ((64, 45), 408.10312, [-0.0642230, 0.1954284, -0.2984768]),
    "actor:module.0.module.mlp.2.weight": ((64, 64), 580.25940, [-0.0350631, -0.0542964, -0.0507446]),
    "actor:module.0.module.mlp.4.weight": ((4, 64), 0.2587920, [0.000756, -6.63e-05, 0.0006959]),
    "critic:module.mlp.0.weight": ((64, 45), 407.06229, [0.2198626, 0.2860771, 0.2685727]),
    "critic:module.mlp.2.weight": ((64, 64), 580.30383, [-0.1207350, 0.0509477, 0.0480773]),
    "critic:module.mlp.4.weight": ((1, 64), 6.7478065, [-0.0934519, 0.0232873, 0.2371279]),
}
#: First reset observation of each env of the first batch (worker 0's two envs, then worker 1's): its
#: sum and L1 norm. Seeded numpy and PyBullet only, no policy involved.
SMOKE_FIRST_OBS = [
    (3.9892926, 9.8073111),
    (4.8802624, 9.4366169),
    (4.0817728, 9.9534740),
    (4.4125991, 10.040336),
]


def test_guard_the_composed_smoke_config(train_cfg) -> None:
    cfg = OmegaConf.to_container(train_cfg("experiment=smoke"), resolve=True)
    env = cfg.pop("env")
    del cfg["paths"]["output_dir"]
    assert flatten(cfg) == flatten(OmegaConf.to_container(OmegaConf.create(SMOKE_CONFIG)))
    # the env node: the group choices over EnvConfig's own defaults
    defaults = {k: v for k, v in OmegaConf.to_container(OmegaConf.structured(EnvConfig)).items()}
    lift = {"_target_": "rlgrasp.envs.tasks.LiftTask", "reward": "dense", "success_height": 0.05}
    lift |= {"terminate_on_success": False, "weights": None}  # configs/task/lift.yaml
    assert env == {**defaults, "randomization": "default", "objects": "cube", "task": lift}


def test_guard_the_spec_and_the_seeded_initial_networks(tmp_path: Path, train_cfg) -> None:
    """The Trainer seeds before it builds the networks (no workers start)."""
    trainer = Trainer(train_cfg("experiment=smoke", "logger=none"))
    assert trainer.parts.spec == SMOKE_SPEC
    params = {f"actor:{k}": v for k, v in trainer.actor.named_parameters()}
    params |= {f"critic:{k}": v for k, v in trainer.parts.critic.named_parameters()}
    for name, (shape, l1, first) in SMOKE_INIT.items():
        weight = params[name].detach()
        assert tuple(weight.shape) == shape, name
        assert float(weight.abs().sum()) == pytest.approx(l1, rel=1e-4), name
        assert weight.flatten()[:3].tolist() == pytest.approx(first, rel=1e-4, abs=1e-6), name
    assert len(params) == 2 * len(SMOKE_INIT) + 1  # a bias per weight, and the actor's log-std
    assert all(not params[k].any() for k in params if k.endswith(".bias"))


@pytest.mark.full  # starts the process collector's workers
def test_guard_the_first_observations_of_the_seeded_workers(tmp_path: Path, train_cfg) -> None:
    """The first batch's first step, through the configured process collector: each worker's envs
    reset with their own seeds, whatever the policy then does."""
    cfg = train_cfg("experiment=smoke")
    parts = build_parts(cfg)
    collector = parts.make_collector(0, str(tmp_path / "errors"))
    try:
        batch = next(iter(collector))
    finally:
        collector.shutdown()
    first = batch.reshape(-1, batch.shape[-1])["observation"][:, 0]
    got = [(float(o.sum()), float(o.abs().sum())) for o in first]
    assert len(got) == len(SMOKE_FIRST_OBS)
    for env, (have, want) in enumerate(zip(got, SMOKE_FIRST_OBS)):
        assert have == pytest.approx(want, abs=1e-5), f"env {env}"
