"""PPO fine-tuning from a trained policy (``algo.init_from``, ``rlgrasp.train.warm_start``), the
critic's warm-up (``algo.schedule.critic_warmup_frames``) and the teacher's term
(``algo.terms.teacher.checkpoint``): the actor starts as the checkpoint's, its std as the run's
config says, during the warm-up only the critic learns, and the teacher's term pulls the actor
towards the teacher."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.policy_file import load_checkpoint
from rlgrasp.train.loop import Trainer, train
from rlgrasp.train.warm_start import STD_KEY
from rlgrasp.vision.teacher_term import TeacherImitation

SMOKE = ["experiment=smoke", "logger=none"]
STUDENT = Path(__file__).resolve().parents[1] / "policies" / "grasp_vision_depth.pt"


def _params(state: dict[str, torch.Tensor], actor: torch.nn.Module) -> dict[str, torch.Tensor]:
    """The actor's trained parameters in a state dict (not its normalizer's statistics)."""
    names = {n for n, _ in actor.named_parameters()}
    return {k: v for k, v in state.items() if k in names}


def test_the_shipped_depth_student_starts_a_camera_ppo_run(tmp_path: Path, train_cfg) -> None:
    cfg = train_cfg("experiment=grasp_vision_finetune", "logger=none")
    trainer = Trainer(cfg)  # builds and warm-starts, starts no worker
    shipped = load_checkpoint(STUDENT)["actor"]
    here = trainer.actor.state_dict()
    stds = [k for k in here if k.endswith(STD_KEY)]
    assert len(stds) == 1
    for key, value in shipped.items():
        if key not in stds:
            assert torch.equal(here[key], value), key
    fresh = Trainer(train_cfg("experiment=grasp_vision_finetune", "logger=none", "algo.init_from=null"))
    assert torch.equal(here[stds[0]], fresh.actor.state_dict()[stds[0]])  # the run's init_log_std
    assert not torch.equal(here[stds[0]], shipped[stds[0]])  # not the student's
    first_layer = "module.0.module.mlp.0.weight"
    assert not torch.equal(fresh.actor.state_dict()[first_layer], shipped[first_layer])  # a real load


@pytest.mark.full  # a smoke run on process workers
def test_during_the_critic_warm_up_only_the_critic_learns(tmp_path: Path, train_cfg) -> None:
    start = tmp_path / "start"
    Trainer(train_cfg(*SMOKE, run_dir=start)).save()
    before = load_checkpoint(start)
    run = tmp_path / "warm"
    train(
        train_cfg(*SMOKE, f"algo.init_from={start}", "algo.schedule.critic_warmup_frames=2048", run_dir=run)
    )
    after = load_checkpoint(run)
    actor = Trainer(train_cfg(*SMOKE, run_dir=tmp_path / "probe")).actor
    assert _params(after["actor"], actor).keys() == _params(before["actor"], actor).keys() != set()
    for key, value in _params(before["actor"], actor).items():
        assert torch.equal(after["actor"][key], value), f"{key} moved during the warm-up"
    critic = before["ppo"]["critic"]
    moved = [
        k
        for k, v in critic.items()
        if v.is_floating_point() and not torch.equal(after["ppo"]["critic"][k], v)
    ]
    assert any(k.endswith("weight") for k in moved), "the critic did not learn"


TEACHER = Path(__file__).resolve().parents[1] / "policies" / "grasp_ppo.pt"


def test_the_teacher_term_pulls_the_student_towards_its_teacher(train_cfg) -> None:
    """``algo.terms.teacher.checkpoint``: each minibatch's loss gains the squared error to the
    teacher's action on the minibatch's privileged state, weighted coeff * decay**k; its gradient
    moves the actor alone."""
    cfg = train_cfg(
        "experiment=grasp_vision_finetune",
        "logger=none",
        f"algo.terms.teacher.checkpoint={TEACHER}",
        "algo.terms.teacher.coeff=2.0",
        "algo.terms.teacher.decay=0.5",
    )
    trainer = Trainer(cfg)  # starts no worker
    (term,) = [x for x in trainer.algo.learner.extras if isinstance(x, TeacherImitation)]
    assert term.start(TensorDict(), updates=3) == {"charts/teacher_weight": 2.0 * 0.5**3}
    spec, g = trainer.parts.spec, torch.Generator().manual_seed(0)
    minibatch = TensorDict(
        {
            "observation": torch.randn(64, spec["obs_dim"], generator=g),
            "depth": torch.rand(64, 1, 64, 64, generator=g),
            "privileged": torch.randn(64, spec["privileged_dim"], generator=g),
        },
        [64],
    )
    teacher_before = {k: v.clone() for k, v in term.teacher.state_dict().items()}
    loss, logged = term.loss(minibatch)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        student = trainer.actor(minibatch.clone())["action"]
    label = term.teacher(minibatch.clone())["action"]
    assert torch.allclose(loss, 0.25 * ((student - label) ** 2).mean(), rtol=1e-4)
    assert logged["teacher_mse"] > 0
    optimizer = torch.optim.Adam(trainer.actor.parameters(), lr=1e-3)
    for _ in range(20):
        optimizer.zero_grad()
        term.loss(minibatch)[0].backward()
        optimizer.step()
    assert term.loss(minibatch)[1]["teacher_mse"] < 0.5 * logged["teacher_mse"]
    assert all(torch.equal(v, teacher_before[k]) for k, v in term.teacher.state_dict().items())
