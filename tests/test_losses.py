"""SAC's and TQC's hand-written losses (``rlgrasp.algos.sac.losses``, ``rlgrasp.algos.tqc.losses``) on
the batched critics (``rlgrasp.algos.sac.critics``) against TorchRL's ``SACLoss`` and ``TQCLoss`` on the
same parameters and minibatch: the same critic, actor and temperature losses and the same gradients
(within float tolerance: the sums run in another order), the same soft update; and a checkpoint
written with TorchRL's losses (the layout before) loads and resumes."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.objectives import SACLoss, SoftUpdate, TQCLoss

from rlgrasp.algos.sac import SAC
from rlgrasp.algos.sac.critics import CriticEnsemble
from rlgrasp.algos.sac.losses import TORCHRL_PREFIXES
from rlgrasp.algos.tqc import TQC
from rlgrasp.compose import compose_train
from rlgrasp.train.parts import build_parts
from tests.sac_reference import build_qvalue

TINY = [
    "logger=none",
    "collector=single",
    "algo.optim.batch_size=32",
    "algo.replay.learning_starts=0",
    "model.hidden_sizes=[16,16]",
    "algo.critic.hidden_sizes=[16,16]",
    "device=cpu",
]
SAC_RUN = ["experiment=grasp_sac", *TINY, "algo.loss.num_critics=3"]
TQC_RUN = [
    "experiment=grasp_tqc",
    *TINY,
    "algo.loss.num_critics=3",
    "algo.loss.n_quantiles=5",
    "algo.loss.top_quantiles_to_drop_per_net=1",
]
CAMERA_RUN = [
    "experiment=grasp_vision_sac",
    *TINY,
    "model.channels=[4,4,4]",
    "model.image_features=8",
    "algo.replay.buffer_frames=256",
]
CLOSE = {"rtol": 1e-5, "atol": 1e-6}


def _learner(tmp_path: Path, overrides: list[str]) -> SAC:
    cfg = compose_train([*overrides, f"paths.output_dir={tmp_path}"])
    torch.manual_seed(0)
    return (TQC if cfg.algo.name == "tqc" else SAC)(cfg, build_parts(cfg), torch.device("cpu"))


def _transitions(algo: SAC, n: int) -> TensorDict:
    """``n`` random flat transitions (a quarter terminated), with a camera's images and privileged state."""
    spec = algo.parts.spec
    td = TensorDict(
        {
            "observation": torch.randn(n, spec["obs_dim"]),
            "action": torch.rand(n, len(spec["action_low"])) * 2 - 1,
            "next": {
                "observation": torch.randn(n, spec["obs_dim"]),
                "reward": torch.rand(n, 1),
                "done": torch.arange(n).unsqueeze(-1) % 4 == 0,
                "terminated": torch.arange(n).unsqueeze(-1) % 4 == 0,
            },
        },
        [n],
    )
    for part in (td, td["next"]):
        for key, shape in spec.get("images", {}).items():
            part[key] = torch.rand(n, *shape)
        if "privileged_dim" in spec and algo.images:
            part["privileged"] = torch.randn(n, spec["privileged_dim"])
    return td


def _perturbed(algo: SAC) -> None:
    """Critics, targets and temperature away from their start (the targets apart from the critics),
    and normalizers that do something, so that no term of the losses is trivially equal."""
    with torch.no_grad():
        for p in [*algo.loss.critics.parameters(), *algo.loss.target_critics.parameters()]:
            p.add_(0.1 * torch.randn_like(p))
        algo.loss.log_alpha.fill_(math.log(0.3))
    for norm in {id(n): n for n in (algo.norm, algo.loss.critics.norm)}.values():
        norm.update(2.0 + 3.0 * torch.randn(64, norm.mean.shape[-1]))


def _reference(algo: SAC) -> SACLoss:
    """TorchRL's loss (``TQCLoss`` for TQC) on the same actor, with our critics' parameters, targets and
    temperature copied in under TorchRL's names."""
    ours, cfg = algo.loss, algo.cfg.algo
    template = build_qvalue(
        ours.critics.norm,
        [*ours.critic_keys, "action"],
        ours.critics.mlp[0].weight.shape[-1],
        cfg.critic,
        algo.critic_outputs,
    )
    kwargs = {
        "num_qvalue_nets": cfg.loss.num_critics,
        "alpha_init": cfg.loss.alpha_init,
        "target_entropy": ours.target_entropy,
    }
    if isinstance(algo, TQC):
        drop = cfg.loss.top_quantiles_to_drop_per_net
        reference = TQCLoss(ours.actor, template, top_quantiles_to_drop_per_net=drop, **kwargs)
    else:
        reference = SACLoss(ours.actor, template, loss_function="l2", **kwargs)
    reference.make_value_estimator(gamma=cfg.loss.gamma)
    state = reference.state_dict()
    mine = ours.state_dict()
    for key in state:
        for old, new in TORCHRL_PREFIXES.items():
            if key.startswith(old):
                state[key] = mine[new + key[len(old) :]].clone()
    state["log_alpha"] = mine["log_alpha"].clone()
    reference.load_state_dict(state)
    return reference


def _critic_grads(module: torch.nn.Module | TensorDictBase) -> dict[str, torch.Tensor]:
    """The gradients by parameter name (TorchRL's ``("module", "mlp", "0", "weight")``: ``mlp.0.weight``)."""
    if isinstance(module, TensorDictBase):  # TorchRL's parameters (a TensorDictParams is a Module too)
        return {".".join(k[1:]): p.grad.clone() for k, p in module.items(True, True) if p.grad is not None}
    return {n: p.grad.clone() for n, p in module.named_parameters() if p.grad is not None}


def _actor_grads(algo: SAC) -> list[torch.Tensor]:
    grads = [p.grad.clone() for p in algo.loss.actor.parameters() if p.requires_grad]
    algo.loss.actor.zero_grad(set_to_none=True)
    return grads


def _minibatch(algo: SAC, n: int = 32) -> TensorDict:
    """The minibatch as the losses read it: with a camera, the images' features added (``_inputs``)."""
    algo.store(_transitions(algo, n))
    return algo._inputs(algo.replay.sample())[0]


@pytest.mark.parametrize("run", [SAC_RUN, TQC_RUN, CAMERA_RUN], ids=["sac", "tqc", "camera"])
def test_the_losses_and_their_gradients_are_torchrls(tmp_path: Path, run: list[str]) -> None:
    algo = _learner(tmp_path, run)
    _perturbed(algo)
    batch = _minibatch(algo).detach()
    reference = _reference(algo)
    ours = algo.loss

    torch.manual_seed(1)  # both draw the next actions from the actor: the same draws
    critic = ours.critic_loss(batch.clone())
    torch.manual_seed(1)
    theirs, _ = reference.qvalue_v2_loss(batch.clone())
    torch.testing.assert_close(critic, theirs, **CLOSE)
    critic.backward()
    theirs.backward()
    mine, torchrl = _critic_grads(ours.critics), _critic_grads(reference.qvalue_network_params)
    assert mine.keys() == torchrl.keys() and len(mine) > 0
    for name in mine:
        torch.testing.assert_close(mine[name], torchrl[name], **CLOSE, msg=name)
    assert all(p.grad is None for p in ours.target_critics.parameters())

    ours.critics.zero_grad(set_to_none=True)
    torch.manual_seed(2)
    actor, log_prob = ours.actor_loss(batch.clone())
    actor.backward()
    assert all(p.grad is None for p in ours.critics.parameters())  # through the critics, not into them
    mine_actor = _actor_grads(algo)
    torch.manual_seed(2)
    theirs, info = reference.actor_loss(batch.clone())
    theirs.backward()
    torch.testing.assert_close(actor, theirs, **CLOSE)
    torch.testing.assert_close(log_prob, info["log_prob"], **CLOSE)
    for a, b in zip(mine_actor, _actor_grads(algo), strict=True):
        torch.testing.assert_close(a, b, **CLOSE)

    alpha, theirs = ours.alpha_loss(log_prob), reference.alpha_loss(info["log_prob"]).mean()
    torch.testing.assert_close(alpha, theirs, **CLOSE)
    alpha.backward()
    theirs.backward()
    torch.testing.assert_close(ours.log_alpha.grad, reference.log_alpha.grad, **CLOSE)


def test_the_targets_soft_update_is_torchrls(tmp_path: Path) -> None:
    algo = _learner(tmp_path, SAC_RUN)
    _perturbed(algo)
    reference = _reference(algo)
    tau = algo.cfg.algo.loss.tau
    updater = SoftUpdate(reference, tau=tau)  # it starts by copying the critics into the targets
    targets = reference.target_qvalue_network_params
    with torch.no_grad():
        for name, p in algo.loss.target_critics.named_parameters():
            targets[("module", *name.split("."))].copy_(p)
    algo.loss.soft_update(tau)
    updater.step()
    for name, p in algo.loss.target_critics.named_parameters():
        torch.testing.assert_close(p, targets[("module", *name.split("."))], **CLOSE, msg=name)


def test_the_critics_are_independent_and_read_the_actors_normalizer(tmp_path: Path) -> None:
    """Each critic's slice of the stacked layers is a network of its own (a change to one moves
    only its values), and the critics read the normalizer the actor updates (no copy)."""
    algo = _learner(tmp_path, SAC_RUN)
    critics: CriticEnsemble = algo.loss.critics
    assert critics.norm is algo.norm and algo.loss.target_critics.norm is algo.norm
    inputs = [torch.randn(8, critics.mlp[0].weight.shape[-1] - 5), torch.rand(8, 5)]
    before = critics(*inputs)
    with torch.no_grad():
        critics.mlp[-1].bias[1].add_(1.0)
    after = critics(*inputs)
    torch.testing.assert_close(after[1], before[1] + 1.0)
    torch.testing.assert_close(after[[0, 2]], before[[0, 2]])


@pytest.mark.parametrize("run", [SAC_RUN, TQC_RUN, CAMERA_RUN], ids=["sac", "tqc", "camera"])
def test_a_checkpoint_of_torchrls_losses_loads_and_resumes(tmp_path: Path, run: list[str]) -> None:
    """A learner state as the code before wrote it (TorchRL's loss state dict, Adam over its
    parameters in its order) loads into the new learner: the same critics, targets, temperature and
    optimizer moments, and the next gradient step runs."""
    old = _learner(tmp_path, run)
    _perturbed(old)
    reference = _reference(old)
    trainable = lambda params: [p for p in params.values(True, True) if p.requires_grad]  # noqa: E731
    optimizers = {
        "actor": torch.optim.Adam(trainable(reference.actor_network_params)),
        "critic": torch.optim.Adam(trainable(reference.qvalue_network_params)),
        "alpha": torch.optim.Adam([reference.log_alpha]),
        **({"encoder": torch.optim.Adam(old._encoder().parameters())} if old.images else {}),
    }
    batch = _minibatch(old)
    loss = reference.qvalue_v2_loss(batch)[0] + reference.actor_loss(batch)[0]
    loss.backward()
    for opt in optimizers.values():
        opt.step()
    saved = {
        "loss": reference.state_dict(),
        "optimizers": {k: o.state_dict() for k, o in optimizers.items()},
        "owed": 0.25,
        "replay_sequence": None,
    }
    new = _learner(tmp_path, run)
    new.load_state_dict(saved)
    params = reference.qvalue_network_params
    for name, p in new.loss.critics.named_parameters():
        assert torch.equal(p, params[("module", *name.split("."))]), name
    for name, p in new.loss.target_critics.named_parameters():
        assert torch.equal(p, reference.target_qvalue_network_params[("module", *name.split("."))]), name
    assert torch.equal(new.loss.log_alpha, reference.log_alpha) and new.owed == 0.25
    for part in ("critic", "actor"):  # the moments by position: the parameters in TorchRL's order
        moments, old_moments = (
            new.optimizers[part].state_dict()["state"],
            optimizers[part].state_dict()["state"],
        )
        for i, p in enumerate(new.optimizers[part].param_groups[0]["params"]):
            assert moments[i]["exp_avg"].shape == p.shape
            assert torch.equal(moments[i]["exp_avg"], old_moments[i]["exp_avg"])
    new.store(_transitions(new, 64))
    assert all(math.isfinite(v) for v in new._step().values())


def _pairwise_quantile_huber(atoms: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """TorchRL's ``TQCLoss`` critic loss as it writes it: over the tensor of every (atom, target) pair."""
    delta = target.unsqueeze(0).unsqueeze(-2) - atoms.unsqueeze(-1)
    huber = torch.where(delta.abs() <= 1, 0.5 * delta.square(), delta.abs() - 0.5)
    n = atoms.shape[-1]
    tau = ((torch.arange(n, dtype=atoms.dtype) + 0.5) / n).view(n, 1)
    weight = (tau - (delta.detach() < 0).to(atoms.dtype)).abs()
    return (weight * huber).mean(dim=(-1, -2)).sum(0).mean()


def test_the_quantile_huber_loss_without_pairs_is_the_pairwise_one() -> None:
    """Targets far below, near and far above the atoms, some exactly 1 away or equal (the runs' ends),
    unsorted: the same loss and gradient as over every pair."""
    from rlgrasp.algos.tqc.losses import quantile_huber_loss

    torch.manual_seed(0)
    atoms = (3.0 * torch.randn(3, 16, 7)).round(decimals=1).requires_grad_()
    target = torch.cat(
        [3.0 * torch.randn(16, 9), atoms[0, :, :3].detach() + 1.0, atoms[1, :, :2].detach()], -1
    )
    ours = quantile_huber_loss(atoms, target)
    (grad,) = torch.autograd.grad(ours, atoms)
    theirs = _pairwise_quantile_huber(atoms, target)
    (expected,) = torch.autograd.grad(theirs, atoms)
    torch.testing.assert_close(ours, theirs, **CLOSE)
    torch.testing.assert_close(grad, expected, **CLOSE)
