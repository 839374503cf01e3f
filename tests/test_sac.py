"""SAC on the training core (``rlgrasp.algos.sac``): the update-to-data ratio, what it learns on a toy
batch, demonstrations in each minibatch (RLPD), resume with the replay buffer, and a short run whose
checkpoint evaluation and export take as they take PPO's."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import ExplorationType, set_exploration_type

from rlgrasp.algos.sac import SAC
from rlgrasp.algos.sac.replay_files import LEGACY_FILE, REPLAY_DIR, ReplayFiles
from rlgrasp.compose import compose_config, compose_train
from rlgrasp.config import ConfigError
from rlgrasp.demos.cli import record_demos
from rlgrasp.demos.dataset import DemoError, demo_transitions, load_demos
from rlgrasp.policy_file import load_checkpoint
from rlgrasp.train.algorithm import algorithm_class
from rlgrasp.train.loop import Trainer, train
from rlgrasp.train.parts import build_parts
from rlgrasp.train.resume import prepare_run
from rlgrasp.train.validate import validate_train

#: A SAC run small enough for a test: one in-process worker, tiny networks, updates from the start.
SMALL = [
    "experiment=grasp_sac",
    "logger=none",
    "collector=single",
    "collector.envs_per_worker=2",
    "collector.steps_per_env=32",
    "total_frames=256",
    "algo.replay.learning_starts=64",
    "algo.optim.batch_size=32",
    "model.hidden_sizes=[16,16]",
    "algo.critic.hidden_sizes=[16,16]",
    "eval.interval_frames=0",
    "eval.episodes=1",
    "eval.final_episodes=2",
    "eval.num_envs=1",
    "checkpoint.interval_frames=128",
    "device=cpu",
]


def _sac(tmp_path: Path, *overrides: str) -> SAC:
    cfg = compose_train([*SMALL, f"paths.output_dir={tmp_path}", *overrides])
    torch.manual_seed(0)
    return SAC(cfg, build_parts(cfg), torch.device("cpu"))


def _batch(sac: SAC, n: int, reward_of=None) -> TensorDict:
    """``n`` random transitions in the collector's ``[envs, time]`` layout (here ``[1, n]``)."""
    obs_dim, act_dim = sac.parts.spec["obs_dim"], len(sac.parts.spec["action_low"])
    action = torch.rand(n, act_dim) * 2 - 1
    reward = reward_of(action) if reward_of else torch.rand(n, 1)
    false = torch.zeros(n, 1, dtype=torch.bool)
    return TensorDict(
        {
            "observation": torch.randn(n, obs_dim),
            "action": action,
            "sample_log_prob": torch.zeros(n),
            "next": {
                "observation": torch.randn(n, obs_dim),
                "reward": reward,
                "done": false,
                "terminated": false,
            },
        },
        [n],
    ).unsqueeze(0)


def test_the_update_to_data_ratio_is_kept_across_batches_of_any_size(tmp_path: Path) -> None:
    sac = _sac(tmp_path, "algo.optim.utd_ratio=0.3", "algo.replay.learning_starts=10")
    steps = [sac.update(_batch(sac, n), 0).get("charts/gradient_steps", 0.0) for n in (8, 7, 7, 9, 5)]
    assert steps[0] == 0  # the buffer holds fewer than learning_starts frames
    # 28 frames after the start, at 0.3 steps a frame: 8 steps, none lost to rounding
    assert sum(steps) == int(0.3 * 28) and sac.updates == int(0.3 * 28)


def test_the_actor_learns_the_action_the_reward_pays_for(tmp_path: Path) -> None:
    """Reward = -|action - 0.5| on every dimension: after a few hundred steps the deterministic
    action has moved towards 0.5 from the initial policy's 0."""
    sac = _sac(
        tmp_path,
        "algo.optim.utd_ratio=1",
        "algo.replay.learning_starts=0",
        "algo.loss.gamma=0.5",
        "algo.optim.actor_lr=3e-3",
        "algo.optim.critic_lr=3e-3",
        "algo.loss.alpha_init=0.01",
    )
    paid = lambda a: -(a - 0.5).abs().mean(-1, keepdim=True)  # noqa: E731
    before = sac.actor.module[0](TensorDict({"observation": torch.zeros(1, sac.parts.spec["obs_dim"])}, [1]))
    for _ in range(12):
        sac.update(_batch(sac, 48, paid), 0)
    after = sac.actor.module[0](TensorDict({"observation": torch.zeros(1, sac.parts.spec["obs_dim"])}, [1]))
    start, end = torch.tanh(before["loc"]).mean(), torch.tanh(after["loc"]).mean()
    assert float(end) > float(start) + 0.2


def test_demonstrations_fill_their_share_of_each_minibatch(tmp_path: Path, recorded_demos: Path) -> None:
    sac = _sac(
        tmp_path, f"algo.demos={recorded_demos}", "algo.replay.demo_ratio=0.25", "env.control.ee_yaw=false"
    )
    demos = demo_transitions(load_demos(recorded_demos, _layout_of(sac)), sac.cfg.env)
    sac.update(_batch(sac, 64), 0)
    sample = sac._sample()
    assert sample.numel() == 32
    demo_obs = {tuple(row.tolist()) for row in demos["observation"]}
    from_demos = sum(tuple(row.tolist()) in demo_obs for row in sample["observation"])
    assert from_demos == 8


def test_the_bc_term_pulls_the_actor_to_the_demonstrated_actions(
    tmp_path: Path, recorded_demos: Path
) -> None:
    """``algo.terms.imitation.coeff`` > 0: after the same updates on the same data, the actor's deterministic
    action on the demonstrations' observations is nearer the demonstrated actions than without it."""

    def distance_after(bc_coeff: float) -> tuple[float, dict[str, float]]:
        sac = _sac(
            tmp_path,
            f"algo.demos={recorded_demos}",
            f"algo.terms.imitation.coeff={bc_coeff}",
            "env.control.ee_yaw=false",
            "algo.optim.utd_ratio=1",
            "algo.replay.learning_starts=0",
            "algo.optim.actor_lr=3e-3",
        )
        demos = demo_transitions(load_demos(recorded_demos, _layout_of(sac)), sac.cfg.env)
        torch.manual_seed(1)
        metrics = [sac.update(_batch(sac, 40), 0) for _ in range(5)][-1]
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            acted = sac.actor(demos.select("observation").clone())["action"]
        return float((acted - demos["action"]).pow(2).mean()), metrics

    without, metrics_without = distance_after(0.0)
    with_bc, metrics_with = distance_after(10.0)
    assert with_bc < 0.7 * without
    assert "loss_bc" in metrics_with and "loss_bc" not in metrics_without


def test_pretraining_clones_the_demonstrations_before_the_first_frame(
    tmp_path: Path, recorded_demos: Path
) -> None:
    sac = _sac(
        tmp_path, f"algo.demos={recorded_demos}", "algo.pretrain.epochs=30", "env.control.ee_yaw=false"
    )
    demos = demo_transitions(load_demos(recorded_demos, _layout_of(sac)), sac.cfg.env)

    def distance() -> float:
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            acted = sac.actor(demos.select("observation").clone())["action"]
        return float((acted - demos["action"]).pow(2).mean())

    before, logged = distance(), {}
    sac.start(lambda metrics, frames: logged.update(metrics))
    assert distance() < 0.5 * before
    assert logged["pretrain/bc_loss_last"] < logged["pretrain/bc_loss_first"]


def test_demonstrations_become_transitions_with_their_successors(recorded_demos: Path) -> None:
    demos = load_demos(recorded_demos, _layout_of_env(ee_yaw=False))
    frames, transitions = demos.frames, demo_transitions(demos, {"reward": "dense"})
    assert transitions.numel() == frames.numel()
    inside = ~frames["done"]  # within an episode the next observation is the following step's
    following = frames["observation"][1:][inside[:-1]]
    assert torch.equal(transitions["next", "observation"][:-1][inside[:-1]], following)
    assert torch.equal(transitions["next", "reward"].flatten(), frames["reward"])


def test_demonstrations_of_another_reward_are_refused(recorded_demos: Path) -> None:
    demos = load_demos(recorded_demos, _layout_of_env(ee_yaw=False))
    with pytest.raises(
        DemoError,
        match="recorded with task=lift env.task.reward=dense, this run has task=lift env.task.reward=sp",
    ):
        demo_transitions(demos, {"reward": "sparse"})


def test_resume_restores_the_learner_and_its_replay_buffer(tmp_path: Path) -> None:
    run = tmp_path / "run"
    cfg = compose_train([*SMALL, f"paths.output_dir={run}"])
    trainer = Trainer(cfg)
    trainer.update(_batch(trainer.algo, 96))
    trainer.frames = 96
    trainer.save()
    trainer.logger.close()
    assert ReplayFiles(run).exist()
    again = _resumed(run)
    assert len(again.algo.replay) == 96 and again.updates == trainer.updates
    for key, value in trainer.algo.loss.state_dict().items():
        assert torch.equal(value, again.algo.loss.state_dict()[key]), key
    again.logger.close()
    shutil.rmtree(run / REPLAY_DIR)  # without the files: an empty buffer, said in the log
    third = _resumed(run)
    assert len(third.algo.replay) == 0
    third.logger.close()
    assert "starts with an empty replay buffer" in (run / "train.log").read_text()


def _numbered(sac: SAC, first: int, n: int) -> TensorDict:
    """``n`` transitions whose reward numbers them ``first``, ``first + 1``, ... (their order)."""
    batch = _batch(sac, n)
    batch["next", "reward"] = torch.arange(first, first + n, dtype=torch.float32).reshape(1, n, 1)
    return batch


def test_a_checkpoint_writes_its_new_transitions_only_and_a_resume_keeps_their_order(tmp_path: Path) -> None:
    sac = _sac(tmp_path, "algo.replay.buffer_frames=100", "algo.replay.learning_starts=1000")
    ReplayFiles(tmp_path).write(_numbered(sac, 1000, 5).reshape(-1))  # an older run's, in the same folder
    for first in (0, 60, 120):  # 180 transitions through a buffer of 100: it wraps
        sac.store(_numbered(sac, first, 60).reshape(-1))
        sac.save_extra(tmp_path)
        files = ReplayFiles(tmp_path).chunks()
        assert files[-1][1] == 60  # the checkpoint's file holds its 60 new transitions only
    # The oldest file's 60 are all overwritten, but the last checkpoint's buffer still needed them
    # until the newest file's checkpoint exists: they go at the next checkpoint.
    assert [frames for _, frames, _ in ReplayFiles(tmp_path).chunks()] == [60, 60, 60]
    sac.save_extra(tmp_path)  # nothing new: no file, and the oldest one removed
    assert [seq for seq, _, _ in ReplayFiles(tmp_path).chunks()] == [2, 3]
    assert sac.replay_sequence == 3

    resumed = _sac(tmp_path, "algo.replay.buffer_frames=100", "algo.replay.learning_starts=1000")
    resumed.load_replay(tmp_path)
    kept = sorted(resumed.replay[:]["next", "reward"].flatten().tolist())
    assert kept == [float(r) for r in range(80, 180)]  # the newest 100
    resumed.store(_numbered(resumed, 180, 10).reshape(-1))  # the next ones overwrite the oldest
    kept = sorted(resumed.replay[:]["next", "reward"].flatten().tolist())
    assert kept == [float(r) for r in range(90, 190)]


def test_a_run_killed_between_its_replay_file_and_its_checkpoint_resumes_from_the_one_before(
    tmp_path: Path,
) -> None:
    """The replay file goes first, the checkpoint names it: killed between the two, the run resumes
    from the checkpoint before with that checkpoint's transitions, not the orphan file's, and what a
    cut-short write left is removed."""
    run = tmp_path / "run"
    cfg = compose_train([*SMALL, f"paths.output_dir={run}"])
    trainer = Trainer(cfg)
    trainer.update(_numbered(trainer.algo, 0, 40))
    trainer.frames = 40
    trainer.save()
    trainer.logger.close()
    assert load_checkpoint(run / "checkpoints" / "last.pt")["sac"]["replay_sequence"] == 1
    trainer.update(_numbered(trainer.algo, 40, 30))
    trainer.algo.save_extra(run)  # the file of a checkpoint the kill never let be written
    (run / REPLAY_DIR / ".000003_5.pt.tmp").write_bytes(b"half a file")
    assert len(ReplayFiles(run).chunks()) == 2
    again = _resumed(run)
    rewards = sorted(again.algo.replay[:]["next", "reward"].flatten().tolist())
    assert rewards == [float(r) for r in range(40)] and again.frames == 40
    assert [seq for seq, _, _ in ReplayFiles(run).chunks()] == [1]
    assert not list((run / REPLAY_DIR).glob("*.tmp"))
    again.logger.close()
    assert "not part of the checkpoint resumed" in (run / "train.log").read_text()


def test_a_replay_file_that_cannot_be_written_does_not_cost_the_checkpoint(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = tmp_path / "run"
    trainer = Trainer(compose_train([*SMALL, f"paths.output_dir={run}"]))
    trainer.update(_numbered(trainer.algo, 0, 40))
    trainer.frames = 40
    trainer.save()

    def full_disk(*_args: Any) -> None:
        raise OSError(28, "No space left on device")

    trainer.update(_numbered(trainer.algo, 40, 20))
    trainer.frames = 60
    monkeypatch.setattr(ReplayFiles, "write", full_disk)
    trainer.save()
    trainer.logger.close()
    state = load_checkpoint(run / "checkpoints" / "last.pt")
    assert state["frames"] == 60 and state["sac"]["replay_sequence"] == 1  # the file before
    assert "replay file not written ([Errno 28] No space left on device)" in (run / "train.log").read_text()


def test_a_replay_file_written_before_the_chunks_is_read_then_removed(tmp_path: Path) -> None:
    sac = _sac(tmp_path, "algo.replay.buffer_frames=50", "algo.replay.learning_starts=1000")
    old = _numbered(sac, 0, 40).reshape(-1).select(*sac.transition_keys)
    torch.save({"frames": 40, "data": old.to_dict()}, tmp_path / LEGACY_FILE)
    sac.load_replay(tmp_path)
    assert len(sac.replay) == 40
    sac.store(_numbered(sac, 40, 20).reshape(-1))
    sac.save_extra(tmp_path)
    assert (tmp_path / LEGACY_FILE).is_file()  # the new file alone does not hold the buffer's 50
    sac.store(_numbered(sac, 60, 40).reshape(-1))
    sac.save_extra(tmp_path)  # the files now hold 60, but the checkpoint before still needs the old one
    assert (tmp_path / LEGACY_FILE).is_file()
    sac.save_extra(tmp_path)  # the next checkpoint: the newest files cover the buffer
    assert not (tmp_path / LEGACY_FILE).exists()


def test_a_state_learner_keeps_one_thread_and_the_camera_experiments_take_every_core(tmp_path: Path) -> None:
    assert _sac(tmp_path).learner_threads == 1
    assert _sac(tmp_path, "algo.learner_threads=null").learner_threads == (os.cpu_count() or 1)
    for experiment in ("grasp_vision_sac", "grasp_vision_sac_demos"):
        algo = compose_train([f"experiment={experiment}"]).algo
        assert algo.learner_threads is None and algo.encoder.trained_by == "actor"
    ppo_cfg = compose_train(["algo=ppo", "device=cpu", "collector.torch_threads=3"])  # no such key
    ppo = algorithm_class(ppo_cfg.algo)(ppo_cfg, build_parts(ppo_cfg), torch.device("cpu"))
    assert "learner_threads" not in ppo_cfg.algo and ppo.learner_threads == 3


def test_a_ppo_checkpoint_is_not_resumed_as_sac(tmp_path: Path) -> None:
    run = tmp_path / "run"
    ppo = Trainer(compose_train(["experiment=smoke", "logger=none", f"paths.output_dir={run}"]))
    ppo.save()
    ppo.logger.close()
    with pytest.raises(ConfigError, match=r"algo\._target_: the checkpoint has 'rlgrasp\.algos\.ppo\.PPO'"):
        _resumed(run)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("algo.optim.utd_ratio=0", "algo.optim.utd_ratio=0.0: must be > 0"),
        (
            "algo.replay.buffer_frames=16",
            "algo.replay.buffer_frames=16: must be >= algo.optim.batch_size (32)",
        ),
        ("algo.augment.shift=-1", "algo.augment.shift=-1: must be >= 0 (pixels)"),
        ("algo.augment.kind=hue", "algo.augment.kind='hue': must be one of none, colour"),
        (
            "algo.augment.grey=0.5",
            "algo.augment.grey=0.5: must be in [0, 1], and 0 unless algo.augment.kind=colour",
        ),
        ("algo.augment.overlay=1.5", "algo.augment.overlay=1.5: must be in [0, 1] (0: no overlay)"),
        ("algo.learner_threads=0", "algo.learner_threads=0: must be >= 1 or null (every core)"),
        ("algo.encoder.trained_by=images", "algo.encoder.trained_by='images': must be critic, actor or both"),
        ("algo.terms.imitation.coeff=-1", "algo.terms.imitation.coeff=-1.0: must be finite and >= 0"),
        ("algo.pretrain.epochs=3", "algo.pretrain.epochs=3: needs algo.demos=<demonstrations>"),
    ],
)
def test_bad_sac_input_is_one_line(tmp_path: Path, override: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        validate_train(compose_train([*SMALL, f"paths.output_dir={tmp_path}", override]))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_short_sac_run_evaluates_and_exports_like_ppo(tmp_path: Path) -> None:
    from rlgrasp.evaluation.cli import evaluate
    from rlgrasp.export import export, register_export_config

    run = tmp_path / "run"
    success = train(compose_train([*SMALL, f"paths.output_dir={run}"]))
    assert 0.0 <= success <= 1.0
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert last["frames"] == 256 and last["config"]["algo"]["name"] == "sac" and last["updates"] > 0
    metrics = evaluate(
        compose_config(
            "eval",
            [
                f"ckpt={run}",
                "ckpt_kind=last",
                "episodes=2",
                "video=false",
                "plots=false",
                f"out_dir={tmp_path / 'eval'}",
            ],
        )
    )
    assert metrics["episodes"] == 2
    register_export_config()
    results = export(
        compose_config(
            "export", [f"ckpt={run}", "ckpt_kind=last", "format=torchscript", f"out={tmp_path / 'policy.pt'}"]
        )
    )
    assert results["torchscript"]["max_abs_action_diff"] < 1e-5 and (tmp_path / "policy.pt").is_file()


#: A camera SAC run small enough for a test (the wrist depth camera at 64x64).
CAMERA = [
    "experiment=grasp_vision_sac",
    "model.channels=[4,4,4]",
    "model.image_features=8",
    "algo.replay.buffer_frames=1024",
]


def _camera_batch(sac: SAC, n: int) -> TensorDict:
    """``_batch`` with depth images and the privileged state, as a camera env's collector gives them."""
    spec = sac.parts.spec
    batch = _batch(sac, n).squeeze(0)
    for td in (batch, batch["next"]):
        td["depth"] = torch.rand(n, *spec["images"]["depth"])
        td["privileged"] = torch.randn(n, spec["privileged_dim"])
    return batch.unsqueeze(0)


def test_from_pixels_the_critic_trains_the_encoder_and_the_actor_reads_its_features_detached(
    tmp_path: Path,
) -> None:
    from rlgrasp.algos.sac import ACTOR_FEATURES_KEY, FEATURES_KEY
    from rlgrasp.models.cnn import vision_net

    sac = _sac(
        tmp_path,
        *CAMERA,
        "algo.replay.learning_starts=0",
        "algo.optim.utd_ratio=1",
        "algo.encoder.trained_by=critic",
    )
    encoder = vision_net(sac.actor).encoders
    before = [p.detach().clone() for p in encoder.parameters()]
    sac.update(_camera_batch(sac, 32), 0)
    assert sac.updates == 32
    assert any(not torch.equal(a, b) for a, b in zip(before, encoder.parameters()))  # the encoder learned
    stored = sac.replay[:]
    assert stored["depth"].dtype == torch.float16 and stored["next", "depth"].dtype == torch.float16
    for_critic, for_actor = sac._inputs(sac._sample())
    assert for_critic[FEATURES_KEY].requires_grad and not for_actor[FEATURES_KEY].requires_grad
    assert not for_actor[ACTOR_FEATURES_KEY].requires_grad
    assert not for_critic["next", FEATURES_KEY].requires_grad  # the target: no gradient


def test_the_actor_may_train_the_encoder_and_the_critic_then_reads_its_features_detached(
    tmp_path: Path,
) -> None:
    from rlgrasp.algos.sac import ACTOR_FEATURES_KEY, FEATURES_KEY
    from rlgrasp.models.cnn import vision_net

    sac = _sac(tmp_path, *CAMERA, "algo.replay.learning_starts=0", "algo.encoder.trained_by=actor")
    sac.store(_camera_batch(sac, 32).reshape(-1))
    for_critic, for_actor = sac._inputs(sac._sample())
    assert not for_critic[FEATURES_KEY].requires_grad and not for_actor[FEATURES_KEY].requires_grad
    assert for_actor[ACTOR_FEATURES_KEY].requires_grad
    encoder = vision_net(sac.actor).encoders
    loss_qvalue = sac.loss.critic_loss(for_critic)
    loss_qvalue.backward()  # the critics' loss leaves the encoder alone
    assert all(p.grad is None for p in encoder.parameters())
    loss_actor, _ = sac.loss.actor_loss(for_actor)
    loss_actor.backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in encoder.parameters())


def test_replayed_rgb_images_are_recoloured_and_a_depth_camera_refuses_colour(tmp_path: Path) -> None:
    """``algo.augment.kind=colour``: each replayed RGB image its own recolouring (as a DAgger
    student's, rlgrasp/vision/augment.py) on top of its shift; a camera without RGB refuses it when the
    config is checked, before anything is built."""
    rgb = [*CAMERA, "cameras=wrist_rgb", "algo.augment.shift=0"]
    images = torch.randint(0, 256, (64, 3, 64, 64), dtype=torch.uint8)
    plain = _sac(tmp_path, *rgb)._augmented(images, "rgb", target=False)
    assert plain is images  # no shift, no colour: the replayed images as stored
    recoloured = _sac(tmp_path, *rgb, "algo.augment.kind=colour")._augmented(images, "rgb", target=False)
    assert recoloured.shape == images.shape and recoloured.is_floating_point()
    changed = (recoloured - images.float()).abs().flatten(1).amax(1) > 1
    assert changed.float().mean() > 0.5  # most images moved (an identity draw leaves a few near)
    refused = r"^algo\.augment\.kind='colour': recolours RGB images; needs a camera with RGB"
    with pytest.raises(ConfigError, match=refused):
        validate_train(compose_train([*SMALL, *CAMERA, "algo.augment.kind=colour"]))


def test_overlay_blends_the_images_the_losses_read_not_the_targets_next_images(tmp_path: Path) -> None:
    """``algo.augment.overlay``: each replayed RGB image blended with a pattern at its own weight; the
    next images, which the target values are computed from, stay as stored (SVEA's clean targets)."""
    rgb = [*CAMERA, "cameras=wrist_rgb", "algo.augment.shift=0"]
    images = torch.randint(0, 256, (64, 3, 64, 64), dtype=torch.uint8)
    sac = _sac(tmp_path, *rgb, "algo.augment.overlay=0.5")
    overlaid = sac._augmented(images, "rgb", target=False)
    moved = (overlaid - images.float()).abs().flatten(1).mean(1)
    assert overlaid.shape == images.shape and (moved > 0).float().mean() > 0.9
    assert moved.std() > 0.1 * moved.mean()  # a weight per image, not one for the batch
    assert sac._augmented(images, "rgb", target=True) is images
    refused = r"^algo\.augment\.overlay=0\.5: overlays RGB images; needs a camera with RGB"
    with pytest.raises(ConfigError, match=refused):
        validate_train(compose_train([*SMALL, *CAMERA, "algo.augment.overlay=0.5"]))


def test_ground_swap_changes_the_ground_of_the_images_the_losses_read_and_nothing_else(
    tmp_path: Path,
) -> None:
    """``algo.augment.ground_swap``: the replay keeps each image's ground mask (not the next one's;
    the memory estimate counts it), and the images the losses read get other grounds there, the
    object and the arm untouched; the targets' next images keep theirs. Demonstrations recorded
    without the mask, and a camera without it, are refused in one line."""
    from rlgrasp.algos.sac import replay_bytes_per_frame

    out = tmp_path / "rgb"
    camera = ["cameras=wrist_rgb", "env.control.ee_yaw=true"]
    masked = [*camera, "+env.camera.ground_mask=true"]
    record_demos(compose_config("demos", ["episodes=1", f"out={out}", "workers=1", "keep=all", *masked]))
    swap = [*CAMERA, *masked, "algo.augment.shift=0", "algo.optim.batch_size=8"]
    sac = _sac(tmp_path, *swap, "algo.augment.ground_swap=1", f"algo.demos={out / 'demos'}")
    assert "ground_mask" in sac.transition_keys and ("next", "ground_mask") not in sac.transition_keys
    plain_keys = tuple(k for k in sac.transition_keys if k != "ground_mask")
    spec = sac.parts.spec
    mask_bytes = replay_bytes_per_frame(spec, sac.transition_keys) - replay_bytes_per_frame(spec, plain_keys)
    assert mask_bytes == 64 * 64
    demos = sac.demos[:]
    images, mask = demos["rgb"], demos["ground_mask"]
    assert mask.dtype == torch.uint8 and mask.shape[1:] == (1, 64, 64) and mask.float().mean() > 0.3
    swapped = sac._augmented(images, "rgb", target=False, ground_mask=mask)
    ground = mask.bool().expand_as(images)
    assert torch.equal(swapped[~ground], images[~ground])
    assert (swapped != images).flatten(1).any(1).float().mean() > 0.9  # nearly every ground changed
    assert sac._augmented(images, "rgb", target=True, ground_mask=mask) is images
    sac.store(demos[:8].clone())  # online rows as the collector's batch holds them
    sac._inputs(sac._sample())  # both halves of a minibatch carry their masks to the encoder
    unmasked = tmp_path / "unmasked"
    record_demos(compose_config("demos", ["episodes=1", f"out={unmasked}", "workers=1", "keep=all", *camera]))
    with pytest.raises(ConfigError, match=r"recorded without the camera's ground mask, which algo\.augment"):
        _sac(tmp_path, *swap, "algo.augment.ground_swap=0.5", f"algo.demos={unmasked / 'demos'}")
    refused = r"^algo\.augment\.ground_swap=0\.5: needs the camera's ground mask: an RGB camera and \+env"
    with pytest.raises(ConfigError, match=refused):
        validate_train(compose_train([*SMALL, *CAMERA, *camera, "algo.augment.ground_swap=0.5"]))


def _shipped_as_measured(experiment: str, measured_overrides: list[str]) -> Any:
    """``experiment`` composed, after asserting it equals the run the docs measured (its overrides)."""
    from omegaconf import OmegaConf

    measured = compose_train(measured_overrides)
    shipped = compose_train([f"experiment={experiment}"])
    measured.experiment_name = shipped.experiment_name
    assert OmegaConf.to_container(shipped) == OmegaConf.to_container(measured)
    return shipped


_RGB_CUBE_AS_MEASURED = [
    "experiment=grasp_vision_sac_demos",
    "cameras=wrist_rgb_behind",
    "algo.augment.kind=colour",
    "total_frames=61440",
    "model=cnn_keypoints",
    "+env.camera.object_cells=8",
    "algo.terms.aux.coeff=1",
    "algo.terms.aux.parts=[object_cells]",
    "+env.camera.ground_mask=true",
    "algo.augment.ground_swap=0.5",
    "algo.demos=demos/cube_yaw_wrist_rgb_behind_cells_mask/demos",
]


def test_the_rgb_experiment_is_the_measured_overrides_of_the_camera_one() -> None:
    """docs/history/algorithms.md measured the RGB learner on the cube as grasp_vision_sac_demos plus these
    overrides (2026-12-06, seeds 0-2: the camera behind the hand and recoloured replays of
    2026-12-03, then the objects' recipe: the keypoint encoder, the object-cells head and other
    grounds behind half the replayed images, for 61,440 frames); grasp_vision_sac_rgb_demos must
    stay that run, so its figures hold for it."""
    shipped = _shipped_as_measured("grasp_vision_sac_rgb_demos", _RGB_CUBE_AS_MEASURED)
    assert shipped.env.camera is not None and shipped.algo.augment.kind == "colour"
    assert shipped.model.pooling == "keypoints" and shipped.env.camera.object_cells == 8
    assert shipped.env.camera.ground_mask and shipped.algo.augment.ground_swap == 0.5


def test_the_rgb_objects_experiment_is_the_measured_overrides_of_the_rgb_one() -> None:
    """docs/history/algorithms.md measured the RGB learner on many objects as the RGB cube learner of
    2026-12-03 plus these overrides (the runs of 2026-12-05: the keypoint encoder and the object-cells
    head on top of the utd-0.25 run, then a gradient step every eight frames, and bench_learning's
    time budget; then other grounds behind half the replayed images, on demonstrations recorded with
    the ground mask); grasp_objects_vision_sac_rgb_demos is that run, though it now inherits the
    encoder, the head and the swap from grasp_vision_sac_rgb_demos."""
    cube_recipe = [o for o in _RGB_CUBE_AS_MEASURED if not o.startswith(("total_frames=", "algo.demos="))]
    shipped = _shipped_as_measured(
        "grasp_objects_vision_sac_rgb_demos",
        cube_recipe
        + [
            "objects=train_mix",
            "algo.replay.buffer_frames=61440",
            "total_frames=200000",
            "algo.optim.utd_ratio=0.125",
            "eval.interval_frames=20480",
            "time_budget_min=30",
            "algo.demos=demos/train_mix_wrist_rgb_behind_cells_mask/demos",
        ],
    )
    assert shipped.algo.optim.utd_ratio == 0.125 and shipped.env.objects != compose_train([]).env.objects
    assert shipped.model.pooling == "keypoints" and shipped.env.camera.object_cells == 8


def test_the_state_objects_experiment_with_demonstrations_is_the_measured_run() -> None:
    """docs/history/algorithms.md measured grasp_objects_sac with 20 demonstrations as these overrides (and
    bench_learning's time budget), the RGB objects learner's objects and replay size without its
    camera; its gradient steps a frame are its own (a step every four frames, as measured)."""
    shipped = _shipped_as_measured(
        "grasp_objects_sac_demos",
        [
            "experiment=grasp_objects_sac",
            "algo.demos=demos/train_mix_state/demos",
            "algo.replay.learning_starts=512",
            "algo.optim.utd_ratio=0.25",
            "algo.replay.buffer_frames=61440",
            "total_frames=71680",
            "time_budget_min=30",
        ],
    )
    rgb = compose_train(["experiment=grasp_objects_vision_sac_rgb_demos"])
    assert shipped.env.camera is None and shipped.env.objects == rgb.env.objects
    assert shipped.algo.replay.buffer_frames == rgb.algo.replay.buffer_frames


def test_the_auxiliary_head_keeps_its_targets_learns_without_a_privileged_critic_and_needs_a_camera(
    tmp_path: Path,
) -> None:
    from rlgrasp.models.cnn import vision_net

    sac = _sac(
        tmp_path,
        *CAMERA,
        "algo.replay.learning_starts=0",
        "algo.optim.utd_ratio=0.25",
        "algo.critic.privileged=false",
        "algo.terms.aux.coeff=1",
    )
    assert "privileged" in sac.transition_keys  # the targets are kept although the critics do not read them
    head = [p.detach().clone() for p in sac.aux.parameters()]
    sac.update(_camera_batch(sac, 32), 0)
    metrics = sac.update(_camera_batch(sac, 32), 0)
    assert metrics["loss_aux"] > 0
    assert any(not torch.equal(a, b) for a, b in zip(head, sac.aux.parameters()))  # the head learned
    assert not vision_net(sac.actor).encoders["depth"]._forward_hooks  # SAC encodes itself: no taps
    assert "aux" in sac.state_dict()
    with pytest.raises(ConfigError, match=r"^algo.terms.aux.coeff=1.0: .* needs a camera"):
        _sac(tmp_path, "algo.terms.aux.coeff=1")


def test_the_auxiliary_head_can_say_where_the_camera_sees_the_object(tmp_path: Path) -> None:
    """``object_cells`` as the head's target: a camera that reports them gives the head one output per
    cell, read from their slice of the privileged state; a camera that does not is refused in one
    line that says how to turn them on."""
    aux = ["algo.terms.aux.coeff=1", "algo.terms.aux.parts=[object_cells]"]
    sac = _sac(tmp_path, *CAMERA, "+env.camera.object_cells=4", *aux)
    start, stop = sac.parts.spec["privileged_parts"]["object_cells"]
    assert stop - start == 16 and sac.aux.head.out_features == 16
    assert torch.equal(sac.aux.index, torch.arange(start, stop))
    with pytest.raises(ConfigError, match=r"unknown part 'object_cells'; .* \+env.camera.object_cells=8\)$"):
        _sac(tmp_path, *CAMERA, *aux)


def test_an_image_replay_buffer_larger_than_the_memory_is_refused_in_one_line(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        _sac(tmp_path, *CAMERA, "algo.replay.buffer_frames=1000000000")
    message = str(info.value)
    assert message.startswith("algo.replay.buffer_frames=1,000,000,000: the image replay buffer would take ")
    assert message.endswith("lower algo.replay.buffer_frames") and "\n" not in message


@pytest.mark.full  # an end-to-end run: CI's complete suite, out of the quick set (under 5 minutes)
def test_a_short_camera_sac_run_resumes_evaluates_and_exports(tmp_path: Path) -> None:
    from rlgrasp.evaluation.cli import evaluate
    from rlgrasp.export import export, register_export_config

    run = tmp_path / "run"
    train(compose_train([*SMALL, *CAMERA, "total_frames=128", f"paths.output_dir={run}"]))
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert last["kind"] == "vision" and last["updates"] > 0
    cfg, resumed = prepare_run(
        compose_train([*SMALL, *CAMERA, "total_frames=128", f"paths.output_dir={run}", f"resume={run}"])
    )
    again = Trainer(cfg, resumed=resumed)
    assert len(again.algo.replay) == 128 and again.algo.replay[:]["depth"].dtype == torch.float16
    again.logger.close()
    metrics = evaluate(
        compose_config(
            "eval",
            [
                f"ckpt={run}",
                "ckpt_kind=last",
                "episodes=1",
                "video=false",
                "plots=false",
                f"out_dir={tmp_path / 'eval'}",
            ],
        )
    )
    assert metrics["episodes"] == 1
    register_export_config()
    results = export(
        compose_config(
            "export", [f"ckpt={run}", "ckpt_kind=last", "format=torchscript", f"out={tmp_path / 'policy.pt'}"]
        )
    )
    assert results["torchscript"]["max_abs_action_diff"] < 1e-4


def _resumed(run: Path) -> Trainer:
    cfg, resumed = prepare_run(compose_train([*SMALL, f"paths.output_dir={run}", f"resume={run}"]))
    return Trainer(cfg, resumed=resumed)


def _layout_of(sac: SAC) -> dict:
    return _layout_of_env(ee_yaw=bool(sac.cfg.env.control.ee_yaw))


def _layout_of_env(ee_yaw: bool) -> dict:
    from rlgrasp.demos.dataset import layout_of
    from rlgrasp.envs.factory import env_factory

    cfg = compose_train(["experiment=grasp_sac", f"env.control.ee_yaw={ee_yaw}", "paths.output_dir=."])
    env = env_factory(cfg.env)()
    try:
        return layout_of(env, dict(cfg.env))
    finally:
        env.close()


@pytest.fixture(scope="module")
def recorded_demos(tmp_path_factory) -> Path:
    """Two episodes of the scripted expert on the cube, recorded in this process."""
    out = tmp_path_factory.mktemp("demos") / "cube"
    info = record_demos(compose_config("demos", ["episodes=2", f"out={out}", "workers=1", "keep=all"]))
    assert info["kept"] == 2
    return out / "demos"


def test_camera_demonstrations_fill_a_camera_learners_minibatch_and_others_are_refused(
    tmp_path: Path,
) -> None:
    """rlgrasp-demos with a camera records each step's images and privileged state with their
    successors; a camera SAC samples them beside online data; a state run, or a camera run with
    another image size or pose, refuses them naming the images or the view."""
    out = tmp_path / "cam"
    record_demos(
        compose_config(
            "demos",
            [
                "episodes=1",
                f"out={out}",
                "workers=1",
                "keep=all",
                "cameras=wrist_depth",
                "env.control.ee_yaw=true",
            ],
        )
    )
    sac = _sac(tmp_path, *CAMERA, f"algo.demos={out / 'demos'}", "algo.optim.batch_size=8")
    demos = sac.demos[:]
    assert demos["depth"].shape[1:] == (1, 64, 64) and demos["depth"].dtype == torch.float16
    assert not torch.equal(demos["depth"][1], demos["next", "depth"][1])  # the arm moved between them
    assert torch.equal(demos["depth"][1:5], demos["next", "depth"][:4])  # within the episode
    sac.update(_camera_batch(sac, 16), 0)
    assert sac._sample()["privileged"].shape == (8, sac.parts.spec["privileged_dim"])
    # the bc term's gradient reaches the encoders (the actor's own loss reads them detached)
    with_bc = _sac(
        tmp_path,
        *CAMERA,
        f"algo.demos={out / 'demos'}",
        "algo.optim.batch_size=8",
        "algo.terms.imitation.coeff=1",
    )
    with_bc.update(_camera_batch(with_bc, 16), 0)
    with_bc._bc_loss(with_bc._inputs(with_bc._sample())[0]).backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in with_bc._encoder().parameters())
    with pytest.raises(DemoError, match=r"recorded with the images \{'depth': \[1, 64, 64\]\}, this run's "):
        _sac(tmp_path, f"algo.demos={out / 'demos'}")
    with pytest.raises(DemoError, match=r"this run's camera gives \{'depth': \[1, 48, 48\]\}"):
        _sac(
            tmp_path, *CAMERA, f"algo.demos={out / 'demos'}", "+env.camera.width=48", "+env.camera.height=48"
        )
    # same image size, another pose (the camera 5 cm behind the hand): another view, refused too
    with pytest.raises(
        DemoError,
        match=r"camera view .*'eye': \[0\.06, 0\.0, 0\.0\].* camera is .*'eye': \[0\.1, 0\.0, -0\.05\]",
    ):
        _sac(tmp_path, *CAMERA, "cameras=wrist_depth_behind", f"algo.demos={out / 'demos'}")
