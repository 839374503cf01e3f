"""The training core is the same for every algorithm: a fault after the first batch keeps the work and
says where to resume; a non-finite network never reaches a checkpoint; a stop signal saves. Each
case runs for PPO and SAC (DAgger is the same loop: ``rlgrasp.algos.dagger.DAgger``)."""

from __future__ import annotations

import errno
import signal
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from rlgrasp.algos.ppo.schema import PPOConfig
from rlgrasp.compose import compose_train
from rlgrasp.legacy import nest_algo
from rlgrasp.policy_file import read_checkpoint
from rlgrasp.train.algorithm import algorithm_class
from rlgrasp.train.callbacks import Callback
from rlgrasp.train.loop import Trainer, TrainingError
from tests.helpers import ROOT

#: One in-process worker, tiny networks, a few batches: PPO's and SAC's.
SMALL = {
    "ppo": [
        "experiment=smoke",
        "collector=single",
        "collector.envs_per_worker=2",
        "collector.steps_per_env=32",
        "algo.optim.minibatch_size=32",
    ],
    "sac": [
        "experiment=grasp_sac",
        "collector=single",
        "collector.envs_per_worker=2",
        "collector.steps_per_env=32",
        "algo.replay.learning_starts=64",
        "algo.optim.batch_size=32",
        "algo.critic.hidden_sizes=[16,16]",
    ],
}
COMMON = [
    "logger=none",
    "model.hidden_sizes=[16,16]",
    "total_frames=320",
    "eval.interval_frames=0",
    "eval.episodes=1",
    "eval.final_episodes=1",
    "eval.num_envs=1",
    "checkpoint.interval_frames=0",
    "device=cpu",
]


def _trainer(algo: str, run: Path) -> Trainer:
    return Trainer(compose_train([*SMALL[algo], *COMMON, f"paths.output_dir={run}"]))


@pytest.mark.parametrize("algo", sorted(SMALL))
def test_a_fault_after_the_first_batch_saves_and_says_where_to_resume(algo: str, tmp_path: Path) -> None:
    """A full disk while logging the second batch: the first batch's work is in ``last.pt``."""
    trainer = _trainer(algo, tmp_path / "run")
    logged = []

    def scalars(metrics, frames):
        logged.append(frames)
        if len(logged) == 2:
            raise OSError(errno.ENOSPC, "No space left on device")

    trainer.logger.scalars = scalars
    with pytest.raises(TrainingError) as info:
        trainer.run()
    message = str(info.value)
    assert "OSError" in message and "No space left on device" in message and "\n" not in message
    assert f"resume with resume={tmp_path / 'run'}" in message
    saved = torch.load(tmp_path / "run" / "checkpoints" / "last.pt", weights_only=True)
    assert saved["frames"] == trainer.frames > 0 and saved["config"]["algo"]["name"] == algo


@pytest.mark.parametrize("algo", sorted(SMALL))
def test_a_non_finite_network_stops_the_run_before_any_checkpoint(algo: str, tmp_path: Path) -> None:
    trainer = _trainer(algo, tmp_path / "run")
    update = trainer.algo.update

    def poisoned(batch, frames):
        metrics = update(batch, frames)
        with torch.no_grad():
            next(iter(trainer.actor.parameters())).fill_(float("nan"))
        return metrics

    trainer.algo.update = poisoned
    with pytest.raises(TrainingError, match="non-finite values in the network parameters"):
        trainer.run()
    assert not (tmp_path / "run" / "checkpoints" / "last.pt").exists()


@pytest.mark.parametrize("algo", sorted(SMALL))
def test_a_stop_signal_saves_and_returns(algo: str, tmp_path: Path) -> None:
    trainer = _trainer(algo, tmp_path / "run")
    update = trainer.algo.update

    def stopped(batch, frames):
        trainer.signals.received = signal.SIGTERM  # as the handler records a scheduler's signal
        return update(batch, frames)

    trainer.algo.update = stopped
    trainer.run()
    saved = torch.load(tmp_path / "run" / "checkpoints" / "last.pt", weights_only=True)
    assert 0 < saved["frames"] < 320


class Recorder(Callback):
    """A callback beside the loop: what the Trainer called, in order, and its own checkpoint entry."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.batches = 0

    def on_batch_end(self, host, metrics) -> None:
        self.batches += 1
        self.calls.append("batch")
        metrics["recorder/batches"] = self.batches

    def state_dict(self) -> dict:
        return {"recorder": {"batches": self.batches}}

    def load_state_dict(self, state) -> None:
        self.calls.append("load")
        self.batches = state.get("recorder", {}).get("batches", 0)

    def on_save(self, run_dir) -> None:
        self.calls.append("save")

    def close(self) -> None:
        self.calls.append("close")


def test_a_callback_is_called_beside_the_loop_and_its_state_resumes(tmp_path: Path) -> None:
    """Each batch's hook adds to the logged metrics, each checkpoint holds the callback's entry and is
    followed by ``on_save``, the run closes it however it ends, and a resume hands its entry back."""
    trainer = _trainer("ppo", tmp_path / "run")
    recorder = Recorder()
    trainer.callbacks.append(recorder)
    logged: list[dict] = []
    scalars = trainer.logger.scalars
    trainer.logger.scalars = lambda metrics, frames: (logged.append(dict(metrics)), scalars(metrics, frames))
    trainer.run()
    assert recorder.batches == 5 and recorder.calls.count("batch") == 5  # 320 frames of 64
    assert recorder.calls[-2:] == ["save", "close"]
    assert [m["recorder/batches"] for m in logged if "recorder/batches" in m] == [1, 2, 3, 4, 5]
    saved = read_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert saved["recorder"] == {"batches": 5}

    again = Recorder()
    resumed = Trainer(trainer.cfg, resumed=saved)
    resumed.callbacks.append(again)
    resumed.load_state_dict(saved)
    assert again.calls == ["load"] and again.batches == 5


def test_every_algorithm_is_named_by_its_target_and_an_unknown_one_is_refused() -> None:
    assert algorithm_class({"_target_": "rlgrasp.algos.sac.SAC"}).name == "sac"
    assert algorithm_class({"name": "ppo"}).name == "ppo"  # a config from before algo._target_
    assert algorithm_class({"name": "distill"}).name == "distill"
    with pytest.raises(TypeError, match="is not an rlgrasp Algorithm"):
        algorithm_class({"_target_": "collections.OrderedDict"})


class ShrinkTheStd:
    """A user's own auxiliary term (``+algo.terms.<name>``): pulls the actor's std down."""

    def __init__(self, actor: torch.nn.Module, coeff: float) -> None:
        self.scale = next(p for n, p in actor.named_parameters() if n.endswith("state_independent_scale"))
        self.coeff, self.calls = coeff, 0

    @classmethod
    def from_config(cls, node, algorithm) -> ShrinkTheStd | None:
        return cls(algorithm.actor, node.coeff) if node.coeff else None

    def trainable(self) -> list:
        return []

    def start(self, batch, updates: int) -> dict[str, float]:
        return {"charts/shrink_the_std": self.coeff}

    def after_gae(self, batch) -> None:
        pass

    def loss(self, minibatch):
        self.calls += 1
        return self.coeff * self.scale.sum(), {}


def test_ppos_terms_are_the_parts_its_config_names(tmp_path: Path) -> None:
    """Each ``algo.terms`` node is built by the class its ``_target_`` names; one that is off
    (coefficient 0, no demonstrations, no teacher) is left out, and one of the user's own joins
    the update."""
    assert list(_trainer("ppo", tmp_path / "a").algo.terms) == []
    mine = f"+algo.terms.mine={{_target_:{__name__}.ShrinkTheStd,coeff:1.0}}"
    overrides = [
        *SMALL["ppo"],
        *COMMON,
        mine,
        "algo.terms.rnd.coeff=0.5",
        f"paths.output_dir={tmp_path / 'b'}",
    ]
    trainer = Trainer(compose_train(overrides))
    assert list(trainer.algo.terms) == ["rnd", "mine"]  # the config's order
    before = trainer.actor.state_dict()["module.0.module.scale.state_independent_scale"].clone()
    trainer.run()
    assert trainer.algo.terms["mine"].calls > 0
    assert (trainer.actor.state_dict()["module.0.module.scale.state_independent_scale"] < before).all()
    saved = torch.load(tmp_path / "b" / "checkpoints" / "last.pt", weights_only=True)
    assert "rnd" in saved["ppo"] and "mine" not in saved["ppo"]  # a term with weights: under its name


def test_a_flat_algo_config_of_before_loads_in_todays_shape() -> None:
    """A checkpoint written before ``algo`` was split by role (``policies/*.pt``) maps key by key."""
    flat = {
        "name": "ppo",
        "lr": 7e-4,
        "target_kl": None,
        "demo_coeff": 0.5,
        "teacher": None,
        "bc_only": False,
    }
    nested = nest_algo(flat)
    assert nested == {
        "name": "ppo",
        "optim": {"lr": 7e-4},
        "schedule": {"target_kl": None},
        "terms": {
            "imitation": {"coeff": 0.5, "_target_": "rlgrasp.demos.bc.Imitation"},
            "teacher": {"checkpoint": None, "_target_": "rlgrasp.vision.teacher_term.TeacherImitation"},
        },
        "pretrain": {"only": False},
    }
    assert nest_algo(nested) == nested  # today's shape comes back unchanged
    assert nest_algo({"name": "distill", "teacher": "t.pt", "augment": "colour"}) == {
        "name": "distill",
        "teacher": "t.pt",
        "augment": {"kind": "colour"},
    }
    shipped = read_checkpoint(ROOT / "policies" / "grasp_ppo.pt")["config"]["algo"]
    algo = OmegaConf.merge(OmegaConf.structured(PPOConfig), shipped)  # every key has its place
    assert algo.optim.lr == 3e-4 and algo.loss.gamma == 0.9 and algo.terms.rnd._target_.endswith("RND")


def test_a_second_process_on_a_run_directory_is_refused_in_one_line(tmp_path: Path) -> None:
    from rlgrasp.config import ConfigError
    from rlgrasp.rundir import run_lock

    run = tmp_path / "run"
    trainer = _trainer("ppo", run)
    with run_lock(run):  # as another training process on the same run would hold it
        with pytest.raises(ConfigError, match=r"is being trained by pid \d+: one process per run directory"):
            trainer.run()
    assert not (run / "checkpoints").exists()


def test_checkpoints_write_last_first_and_a_failed_write_leaves_nothing_behind(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from rlgrasp.train import checkpoint as ckpt_lib

    written = []
    save = ckpt_lib.save_checkpoint
    spy = lambda path, state: written.append(path.name) or save(path, state)  # noqa: E731
    monkeypatch.setattr(ckpt_lib, "save_checkpoint", spy)
    ckpt_lib.write_checkpoints(tmp_path, {"frames": 7, "actor": {}}, keep_last=2, is_best=True)
    assert written == ["last.pt", "ckpt_0000000007.pt", "best.pt"]
    monkeypatch.setattr(ckpt_lib, "save_checkpoint", save)

    def full_disk(state, f):
        f.write(b"half a checkpoint")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", full_disk)
    with pytest.raises(OSError):
        ckpt_lib.write_checkpoints(tmp_path, {"frames": 8, "actor": {}}, keep_last=2, is_best=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best.pt", "ckpt_0000000007.pt", "last.pt"]
    assert torch.load(tmp_path / "last.pt", weights_only=True)["frames"] == 7  # untouched
