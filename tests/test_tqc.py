"""TQC (``rlgrasp.algos.tqc``): its target keeps the configured quantiles (its losses equal TorchRL's
``TQCLoss``: tests/test_losses.py), an update moves the critics and the actor, a checkpoint
round-trips and resumes, and a setting that would drop every quantile is refused in one line before
any worker starts."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from rlgrasp.algos.registry import algorithms
from rlgrasp.algos.tqc import TQC
from rlgrasp.compose import compose_train
from rlgrasp.config import ConfigError
from rlgrasp.policy_file import load_checkpoint
from rlgrasp.train.algorithm import algorithm_class
from rlgrasp.train.loop import Trainer
from rlgrasp.train.parts import build_parts
from rlgrasp.train.resume import prepare_run
from rlgrasp.train.validate import validate_train

ROOT = Path(__file__).resolve().parents[1]
#: A TQC run small enough for a test: in-process collection, tiny networks, few quantiles.
SMALL = [
    "experiment=grasp_tqc",
    "logger=none",
    "collector=single",
    "collector.envs_per_worker=2",
    "collector.steps_per_env=32",
    "total_frames=128",
    "algo.replay.learning_starts=64",
    "algo.optim.batch_size=32",
    "algo.loss.n_quantiles=5",
    "algo.loss.top_quantiles_to_drop_per_net=1",
    "model.hidden_sizes=[16,16]",
    "algo.critic.hidden_sizes=[16,16]",
    "eval.interval_frames=0",
    "eval.episodes=1",
    "eval.final_episodes=1",
    "eval.num_envs=1",
    "checkpoint.interval_frames=64",
    "device=cpu",
]


def _tqc(tmp_path: Path, *overrides: str) -> TQC:
    cfg = compose_train([*SMALL, f"paths.output_dir={tmp_path}", *overrides])
    torch.manual_seed(0)
    return TQC(cfg, build_parts(cfg), torch.device("cpu"))


def _batch(tqc: TQC, n: int) -> TensorDict:
    """``n`` random transitions in the collector's ``[envs, time]`` layout (``[1, n]``)."""
    obs_dim, act_dim = tqc.parts.spec["obs_dim"], len(tqc.parts.spec["action_low"])
    false = torch.zeros(n, 1, dtype=torch.bool)
    return TensorDict(
        {
            "observation": torch.randn(n, obs_dim),
            "action": torch.rand(n, act_dim) * 2 - 1,
            "next": {
                "observation": torch.randn(n, obs_dim),
                "reward": torch.rand(n, 1),
                "done": false,
                "terminated": false,
            },
        },
        [n],
    ).unsqueeze(0)


def test_tqc_is_registered_and_composes_from_its_own_files() -> None:
    assert algorithms()["tqc"].target == "rlgrasp.algos.tqc.TQC"
    cfg = compose_train(["experiment=grasp_tqc"])
    assert algorithm_class(cfg.algo) is TQC and cfg.algo.name == "tqc"
    assert (cfg.algo.loss.n_quantiles, cfg.algo.loss.top_quantiles_to_drop_per_net) == (25, 2)
    assert cfg.algo.optim.utd_ratio == 0.5  # grasp_sac's, which the experiment builds on
    validate_train(cfg)


def test_the_target_keeps_the_configured_quantiles(tmp_path: Path) -> None:
    """The pooled target keeps (n_quantiles - drop) x num_critics atoms per transition (the losses
    themselves are held equal to TorchRL's ``TQCLoss`` in tests/test_losses.py)."""
    tqc = _tqc(tmp_path, "algo.loss.num_critics=3")
    batch = _batch(tqc, 16).reshape(-1)
    assert tqc.loss.target(batch).shape == (16, (5 - 1) * 3)
    assert torch.isfinite(tqc.loss.critic_loss(batch)) and torch.isfinite(tqc.loss.actor_loss(batch)[0])


def test_an_update_moves_the_critics_and_the_actor(tmp_path: Path) -> None:
    tqc = _tqc(tmp_path, "algo.replay.learning_starts=32")
    critics = [p.detach().clone() for p in tqc.loss.critics.parameters()]
    actor = [p.detach().clone() for p in tqc.actor.parameters()]
    metrics = tqc.update(_batch(tqc, 64), 64)
    assert metrics["charts/gradient_steps"] == 0.5 * 64  # grasp_sac's ratio
    after = list(tqc.loss.critics.parameters())
    assert any(not torch.equal(a, b) for a, b in zip(critics, after))
    assert any(not torch.equal(a, b) for a, b in zip(actor, tqc.actor.parameters()))
    assert all(torch.isfinite(torch.tensor(v)) for v in metrics.values())


def test_a_checkpoint_round_trips_and_resumes(tmp_path: Path) -> None:
    run = tmp_path / "run"
    trainer = Trainer(compose_train([*SMALL, f"paths.output_dir={run}"]))
    trainer.update(_batch(trainer.algo, 96))
    trainer.frames = 96
    trainer.save()
    trainer.logger.close()
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    assert state["config"]["algo"]["_target_"] == "rlgrasp.algos.tqc.TQC"
    assert {"loss", "optimizers", "owed", "replay_sequence"} <= set(state["tqc"])
    cfg, resumed = prepare_run(compose_train([*SMALL, f"paths.output_dir={run}", f"resume={run}"]))
    again = Trainer(cfg, resumed=resumed)
    assert isinstance(again.algo, TQC) and len(again.algo.replay) == 96
    assert again.updates == trainer.updates > 0
    for key, value in trainer.algo.loss.state_dict().items():
        assert torch.equal(value, again.algo.loss.state_dict()[key]), key
    again.logger.close()


@pytest.mark.parametrize(
    ("overrides", "line"),
    [
        (
            ["algo.loss.top_quantiles_to_drop_per_net=25"],
            "algo.loss.top_quantiles_to_drop_per_net=25: must be in [0, algo.loss.n_quantiles=25)",
        ),
        (["algo.loss.n_quantiles=0"], "algo.loss.n_quantiles=0: must be >= 1"),
    ],
)
def test_a_quantile_setting_that_keeps_none_is_refused_in_one_line(overrides: list[str], line: str) -> None:
    with pytest.raises(ConfigError) as refused:
        validate_train(compose_train(["experiment=grasp_tqc", *overrides]))
    assert str(refused.value).startswith(line) and "\n" not in str(refused.value)


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_the_command_line_refuses_it_before_any_worker_starts(tmp_path: Path) -> None:
    run = tmp_path / "run"
    args = ["experiment=grasp_tqc", "algo.loss.top_quantiles_to_drop_per_net=30", f"hydra.run.dir={run}"]
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "train.py"), *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "error: algo.loss.top_quantiles_to_drop_per_net=30: must be in [0, algo.loss.n_quantiles=25): the "
        "target keeps (n_quantiles - drop) x num_critics atoms, and dropping n_quantiles or more per critic "
        "keeps none"
    ]
    assert not (run / "checkpoints").exists() and not (run / "tensorboard").exists()
