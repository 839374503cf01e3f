"""Image models and DAgger's pieces, without a training run."""

from __future__ import annotations

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict
from torchrl.envs import ExplorationType, set_exploration_type
from torchrl.objectives import BCLoss

from rlgrasp.config import ConfigError
from rlgrasp.models.cnn import SpatialSoftmax, actor_norm, average_weights, build_vision_actor
from rlgrasp.policy_file import CheckpointError
from rlgrasp.vision.augment import (
    augment,
    ground_bank,
    overlay,
    overlay_bank,
    random_shift,
    recolour,
    swap_ground,
)
from rlgrasp.vision.auxiliary import ObjectFromImages
from rlgrasp.vision.dagger import LABEL_KEY, DAggerPolicy, LabelledFrames, PrivilegedTeacher, load_teacher

MODEL = OmegaConf.create(
    dict(
        hidden_sizes=[32, 32],
        activation="elu",
        channels=[8, 16, 16],
        image_features=32,
        init_log_std=-0.5,
        min_std=0.05,
        obs_norm=True,
        obs_clip=10.0,
    )
)
# The keypoint encoder; MODEL above, without the keys, is how checkpoints before them read.
KEYPOINTS = OmegaConf.merge(MODEL, {"strides": [2, 2, 1], "kernel_sizes": [8, 4, 3], "pooling": "keypoints"})
SPEC = {
    "obs_dim": 5,
    "privileged_dim": 9,
    "images": {"depth": [1, 64, 64], "rgb": [3, 64, 64]},
    "far": 1.0,
    "action_low": [-1.0] * 3,
    "action_high": [1.0] * 3,
}


def frames(n: int) -> TensorDict:
    return TensorDict(
        {
            "observation": torch.randn(n, 5),
            "depth": torch.rand(n, 1, 64, 64),
            "rgb": torch.randint(0, 256, (n, 3, 64, 64), dtype=torch.uint8),
            "privileged": torch.randn(n, 9),
        },
        [n],
    )


class ConstantTeacher(torch.nn.Module):
    """A stand-in state policy: always the same action, whatever it reads."""

    def forward(self, td):
        td["action"] = torch.full((*td.batch_size, 3), 0.5)
        return td


def test_vision_actor_reads_state_and_uint8_images():
    actor = build_vision_actor(SPEC, MODEL, deterministic=True)
    assert set(actor.in_keys) == {"observation", "depth", "rgb"}
    out = actor(frames(4))
    assert out["action"].shape == (4, 3) and out["action"].abs().max() <= 1.0


def test_the_weight_average_moves_a_share_of_the_way_and_copies_the_normalizer():
    torch.manual_seed(0)
    model, average = build_vision_actor(SPEC, MODEL), build_vision_actor(SPEC, MODEL)
    actor_norm(model).update(torch.randn(64, 5) * 3 + 1)
    before = [p.clone() for p in average.parameters()]
    average_weights(average, model, decay=0.9)
    for old, avg, new in zip(before, average.parameters(), model.parameters()):
        torch.testing.assert_close(avg, 0.9 * old + 0.1 * new)
    for avg, buf in zip(average.buffers(), model.buffers()):
        assert torch.equal(avg, buf)


@pytest.mark.parametrize("model", [MODEL, KEYPOINTS], ids=["flat", "keypoints"])
def test_bc_loss_lowers_on_a_fixed_batch(model):
    torch.manual_seed(0)
    actor = build_vision_actor(SPEC, model)
    batch = frames(64)
    batch["action"] = torch.rand(64, 3) * 1.6 - 0.8
    loss, optimizer = BCLoss(actor, loss_function="mse"), torch.optim.Adam(actor.parameters(), 1e-3)
    values = []
    for _ in range(60):
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            value = loss(batch.clone())["loss_bc"]
        optimizer.zero_grad()
        value.backward()
        optimizer.step()
        values.append(float(value))
    assert values[-1] < 0.5 * values[0]


def test_the_spatial_softmax_finds_each_channels_peak():
    maps = torch.zeros(2, 3, 9, 11)
    peaks = [[(0, 0), (4, 5), (8, 10)], [(2, 7), (8, 0), (0, 10)]]  # (row, column) per channel
    for n, channels in enumerate(peaks):
        for c, (row, col) in enumerate(channels):
            maps[n, c, row, col] = 50.0
    points = SpatialSoftmax(9, 11)(maps).reshape(2, 3, 2)
    expected = torch.tensor([[[col / 5 - 1, row / 4 - 1] for row, col in channels] for channels in peaks])
    torch.testing.assert_close(points, expected, atol=1e-3, rtol=0)


def test_the_keypoint_encoder_has_fewer_weights_and_the_same_interface():
    flat, keypoints = build_vision_actor(SPEC, MODEL), build_vision_actor(SPEC, KEYPOINTS)
    assert sum(p.numel() for p in keypoints.parameters()) < sum(p.numel() for p in flat.parameters())
    out = keypoints(frames(4))
    assert out["action"].shape == (4, 3) and set(keypoints.in_keys) == set(flat.in_keys)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"pooling": "max"}, "model.pooling='max': must be one of flat, keypoints"),
        (
            {"strides": [2, 2]},
            r"model.strides=\[2, 2\]: needs one entry per layer of model.channels=\[8, 16, 16\]",
        ),
    ],
)
def test_a_bad_encoder_setting_is_refused_in_one_line(change, message):
    with pytest.raises(ValueError, match=message):
        build_vision_actor(SPEC, OmegaConf.merge(KEYPOINTS, change))


def test_the_auxiliary_head_learns_the_object_from_the_images_alone():
    """The object's offset is written into the depth image (a bright column at its x); the head on
    the encoder's features learns to read it back, trained with the encoder as distillation does."""
    torch.manual_seed(0)
    actor = build_vision_actor(SPEC, MODEL)
    aux = ObjectFromImages(
        actor.module[0].module.encoders, {"object_minus_grasp": [2, 5]}, ["object_minus_grasp"]
    )
    batch = frames(128)
    column = torch.randint(0, 64, (128,))
    batch["depth"] = torch.zeros(128, 1, 64, 64)
    batch["depth"][torch.arange(128), 0, :, column] = 1.0
    batch["privileged"][:, 2] = column.float() / 64  # the part the head must predict
    aux.update(batch)
    optimizer = torch.optim.Adam([*actor.parameters(), *aux.parameters()], 3e-3)
    losses = []
    for _ in range(80):
        actor(batch.clone())  # the student's forward: the head reads the features it tapped
        loss = aux.loss(batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(float(loss))
    assert losses[-1] < 0.3 * losses[0]


def test_an_unknown_auxiliary_part_is_refused_in_one_line():
    actor = build_vision_actor(SPEC, MODEL)
    with pytest.raises(
        ConfigError,
        match="algo.terms.aux.parts: unknown part 'object_pose'; parts of the privileged state: "
        "object_minus_grasp",
    ):
        ObjectFromImages(actor.module[0].module.encoders, {"object_minus_grasp": [2, 5]}, ["object_pose"])


def test_recolouring_permutes_channels_and_scales_brightness():
    rgb = torch.zeros(50, 3, 4, 4, dtype=torch.uint8)
    rgb[:, 0], rgb[:, 1], rgb[:, 2] = 200, 100, 10
    same_light = recolour(rgb, brightness=(1.0, 1.0), contrast=(1.0, 1.0))
    orders = {tuple(int(v) for v in img[:, 0, 0].round()) for img in same_light}
    assert all(sorted(o) == [10, 100, 200] for o in orders) and len(orders) > 1  # permuted, not changed
    dimmer = recolour(rgb, brightness=(0.5, 0.5), contrast=(1.0, 1.0))
    assert torch.allclose(dimmer.sum(1), torch.full((50, 4, 4), 155.0))  # half of 310, every image


def test_recolouring_greys_the_share_asked_for():
    rgb = torch.zeros(400, 3, 4, 4, dtype=torch.uint8)
    rgb[:, 0], rgb[:, 1], rgb[:, 2] = 200, 100, 10
    out = recolour(rgb, brightness=(1.0, 1.0), contrast=(1.0, 1.0), grey=0.5)
    greyed = (out[:, 0] == out[:, 1]).all(-1).all(-1) & (out[:, 1] == out[:, 2]).all(-1).all(-1)
    assert 0.35 < greyed.float().mean() < 0.65  # about half, drawn per image
    luminance = 0.299 * 200 + 0.587 * 100 + 0.114 * 10
    assert torch.allclose(out[greyed], torch.full_like(out[greyed], luminance))
    kept = recolour(rgb, brightness=(1.0, 1.0), contrast=(1.0, 1.0))
    assert (kept[:, 0] != kept[:, 1]).all()  # grey=0: every image keeps its hue


def test_random_shift_moves_each_image_by_whole_pixels_and_repeats_the_border():
    images = torch.arange(64 * 2 * 8 * 8, dtype=torch.int64).reshape(64, 2, 8, 8) % 251
    moved = random_shift(images.to(torch.uint8), 2, torch.Generator().manual_seed(0)).long()
    offsets = set()
    for before, after in zip(images, moved):
        # The offset that explains the middle 4x4 pixels must explain the whole image, border included.
        found = [
            (dy, dx)
            for dy in range(-2, 3)
            for dx in range(-2, 3)
            if torch.equal(after[:, 2:6, 2:6], before[:, 2 + dy : 6 + dy, 2 + dx : 6 + dx])
        ]
        assert len(found) == 1
        dy, dx = found[0]
        rows, cols = (torch.arange(8) + dy).clamp(0, 7), (torch.arange(8) + dx).clamp(0, 7)
        assert torch.equal(after, before[:, rows][:, :, cols])
        offsets.add(found[0])
    assert len(offsets) > 10  # drawn per image, not once per batch


def test_overlay_blends_each_image_toward_a_pattern_of_the_bank_by_its_own_weight():
    rgb = torch.full((200, 3, 8, 8), 128, dtype=torch.uint8)
    bank = overlay_bank(8, 8)
    assert bank.shape == (512, 3, 8, 8) and bank.float().std() > 20  # patterns, not a flat colour
    out = overlay(rgb, 0.5, torch.Generator().manual_seed(0))
    assert out.is_floating_point() and out.shape == rgb.shape
    # Each image is 128 + w (p - 128): one pattern p of the bank, one weight w in [0, 0.5].
    offsets = (bank.float() - 128.0).flatten(1)
    offsets = offsets[(offsets * offsets).sum(1) > 0]
    for image in out[:20]:
        moved = (image - 128.0).flatten()
        weights = offsets @ moved / (offsets * offsets).sum(1)
        errors = (moved - weights[:, None] * offsets).abs().amax(1)
        best = int(errors.argmin())
        assert errors[best] < 1e-2 and -1e-4 <= weights[best] <= 0.5 + 1e-4
    strengths = (out - 128.0).abs().flatten(1).mean(1)
    assert strengths.std() > 0.1 * strengths.mean()  # drawn per image
    sample = frames(4)
    depth = sample["depth"].clone()
    overlaid = augment(sample, "none", overlay_strength=0.5)
    assert overlaid["depth"].equal(depth) and overlaid["rgb"].is_floating_point()  # RGB only


def test_swap_ground_puts_a_pattern_of_the_bank_where_the_mask_says_in_its_share_of_the_images():
    """Each swapped image's ground pixels are one pattern of the bank, the same in each of its
    stacked frames; every other pixel, and every image not drawn, stays as it was."""
    rgb = torch.full((400, 6, 8, 8), 7, dtype=torch.uint8)  # two stacked frames; no bank colour is 7
    mask = torch.zeros(400, 2, 8, 8, dtype=torch.uint8)
    mask[:, 0, 4:] = 1  # the lower half of the older frame is ground, the upper half of the newer
    mask[:, 1, :4] = 1
    out = swap_ground(rgb, mask, 0.5, torch.Generator().manual_seed(0))
    assert out.dtype == torch.uint8 and out.shape == rgb.shape
    ground = mask.bool().repeat_interleave(3, dim=1)
    assert (out[~ground] == 7).all()
    swapped = (out != 7).flatten(1).any(1)
    assert 150 < int(swapped.sum()) < 250  # drawn per image, about half
    bank = ground_bank(8, 8)
    for image in out[swapped][:20]:
        older, newer = image[:3, 4:], image[3:, :4]
        matches = (bank[:, :, 4:] == older).flatten(1).all(1) & (bank[:, :, :4] == newer).flatten(1).all(1)
        assert matches.any()  # one pattern of the bank, in both frames
    assert torch.equal(swap_ground(rgb, mask, 0.0), rgb)


def test_swap_ground_is_exact_for_any_pixel_values_uint8_or_float():
    """The swap is arithmetic (``x + (p - x) g``, wrapping in uint8): over every pixel value, uint8
    and float images come out alike, each pixel either the image's or the pattern's."""
    rgb = torch.randint(0, 256, (64, 3, 8, 8), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    mask = (torch.rand(64, 1, 8, 8, generator=torch.Generator().manual_seed(2)) < 0.5).to(torch.uint8)
    as_uint8 = swap_ground(rgb, mask, 1.0, torch.Generator().manual_seed(3))
    as_float = swap_ground(rgb.float(), mask, 1.0, torch.Generator().manual_seed(3))
    assert as_float.is_floating_point() and torch.equal(as_float, as_uint8.float())
    ground = mask.bool().expand(-1, 3, -1, -1)
    assert torch.equal(as_uint8[~ground], rgb[~ground])
    bank = ground_bank(8, 8)
    for image, where in zip(as_uint8[:16], ground[:16]):
        assert ((bank == image) | ~where).flatten(1).all(1).any()  # one pattern of the bank on the ground


def test_augmentations_stay_on_the_images_device():
    """A camera SAC's replay, and so its images, live on ``device`` (CUDA when present) while the
    random draws are made on the CPU's generator: the meta device stands in for a GPU here (no
    machine in CI has one), and refuses a CPU operand the same way."""
    images = torch.zeros(4, 3, 8, 8, dtype=torch.uint8, device="meta")
    mask = torch.ones(4, 1, 8, 8, dtype=torch.uint8, device="meta")
    swapped = swap_ground(images, mask, 0.5)
    for augmented in (random_shift(images, 2), recolour(images, grey=0.5), overlay(images, 0.5), swapped):
        assert augmented.device == images.device and augmented.shape == images.shape


def test_augment_shifts_depth_and_rgb_images():
    sample = frames(32)
    depth, rgb = sample["depth"].clone(), sample["rgb"].clone()
    out = augment(sample, "none", shift=2)
    assert out["rgb"].dtype == torch.uint8 and not torch.equal(out["rgb"], rgb)
    assert not torch.equal(out["depth"], depth) and torch.isin(out["depth"], depth).all()
    assert augment(out.clone(), "none", shift=0)["rgb"].equal(out["rgb"])


@pytest.mark.parametrize("beta, teacher_share", [(1.0, 1.0), (0.0, 0.0)])
def test_dagger_policy_labels_every_frame_and_mixes_by_beta(beta, teacher_share):
    student = build_vision_actor(SPEC, MODEL)
    policy = DAggerPolicy(student, PrivilegedTeacher(ConstantTeacher()), beta=beta)
    out = policy(frames(200))
    assert torch.all(out[LABEL_KEY] == 0.5)
    acted_as_teacher = (out["action"] == 0.5).all(-1).float().mean()
    assert float(acted_as_teacher) == teacher_share


def test_beta_travels_with_the_weights():
    policy = DAggerPolicy(build_vision_actor(SPEC, MODEL), PrivilegedTeacher(ConstantTeacher()), beta=0.3)
    assert float(policy.state_dict()["beta"]) == pytest.approx(0.3)


def test_labelled_frames_aggregate_up_to_capacity():
    data = LabelledFrames(["observation", "depth"], capacity=100, minibatch=16)
    for _ in range(3):
        batch = frames(40)
        batch[LABEL_KEY] = torch.zeros(40, 3)
        data.extend(batch)
    assert len(data) == 100
    sample = data.sample()
    assert sample.batch_size == (16,) and set(sample.keys()) == {"observation", "depth", LABEL_KEY}


def test_a_teacher_of_another_layout_is_refused():
    spec = dict(SPEC, privileged_dim=45)
    with pytest.raises(CheckpointError, match="it reads 49 state values, this env's privileged state has 45"):
        load_teacher("policies/grasp_objects_ppo.pt", spec, {"control": {"mode": "ee_delta"}})


def test_a_teacher_of_another_control_mode_is_refused():
    spec = dict(SPEC, privileged_dim=49)
    with pytest.raises(
        CheckpointError, match="env.control.mode='joint_delta' in the teacher, 'ee_delta' here"
    ):
        load_teacher("policies/grasp_ppo.pt", spec, {"control": {"mode": "ee_delta", "ee_yaw": False}})


@pytest.mark.parametrize("robot", ["kuka_iiwa", "xarm6"])
def test_a_teacher_of_another_arm_is_refused(robot):
    # The iiwa's state has the Panda's size (7 joints): only the arm's name tells them apart.
    spec = dict(SPEC, privileged_dim=49)
    with pytest.raises(
        CheckpointError, match=f"it was trained on the robot 'panda' and this env has the robot '{robot}'"
    ) as info:
        load_teacher("policies/grasp_ppo.pt", spec, {"control": {"mode": "joint_delta"}, "robot": robot})
    assert "\n" not in str(info.value)
    load_teacher("policies/grasp_ppo.pt", spec, {"control": {"mode": "joint_delta"}, "robot": "panda"})


SMALL_DISTILL = (
    "experiment=grasp_vision_distill",
    "total_frames=2048",
    "collector.envs_per_worker=2",
    "collector.steps_per_env=256",
    "eval.interval_frames=1024",
    "eval.episodes=2",
    "eval.final_episodes=2",
    "eval.num_envs=2",
    "checkpoint.interval_frames=1024",
    "logger=none",
    "time_budget_min=null",
)


@pytest.mark.full  # camera distillation on workers, resumed
def test_distillation_trains_checkpoints_resumes_and_evaluates(tmp_path, train_cfg):
    from rlgrasp.algos.dagger.algorithm import distill
    from rlgrasp.policy_file import load_checkpoint, policy_from_checkpoint

    run = tmp_path / "run"
    with_aux = (
        *SMALL_DISTILL,
        "algo.terms.aux.coeff=0.1",
    )  # the auxiliary head is checkpointed and resumed too
    success = distill(train_cfg(*with_aux, run_dir=run))
    assert 0.0 <= success <= 1.0
    ckpt = load_checkpoint(run)
    assert (
        ckpt["kind"] == "vision"
        and ckpt["frames"] == 2048
        and ckpt["spec"]["images"] == {"depth": [1, 64, 64]}
    )
    assert ckpt["last_eval"]["teacher_success_rate"] >= 0.0 and "head.weight" in ckpt["distill"]["aux"]
    policy = policy_from_checkpoint(ckpt)
    assert set(policy.in_keys) == {"observation", "depth"}
    # The experiment deploys a moving average of the student: both are kept, and they differ.
    trained, deployed = ckpt["distill"]["student"], ckpt["actor"]  # its state under its name
    assert trained.keys() == deployed.keys()
    assert any(not torch.equal(trained[k], deployed[k]) for k in trained)
    distill(train_cfg(*with_aux, f"resume={run}", "total_frames=3072", run_dir=run))
    resumed = load_checkpoint(run)
    assert resumed["frames"] == 3072 and resumed["generation"] == 1 and resumed["updates"] > ckpt["updates"]


@pytest.mark.parametrize(
    "override, match",
    [
        ("algo.teacher=/nowhere/teacher.pt", "/nowhere/teacher.pt"),
        ("algo.schedule.beta_decay=0", "algo.schedule.beta_decay=0.0: must be in (0, 1]"),
        ("algo.schedule.beta0=1.5", "algo.schedule.beta0=1.5: must be in [0, 1]"),
        ("algo.optim.ema_decay=1", "algo.optim.ema_decay=1.0: must be in [0, 1)"),
        ("algo.augment.grey=0.5", "algo.augment.grey=0.5: must be in [0, 1], and 0 unless algo.augment.kind"),
        ("algo.augment.shift=-1", "algo.augment.shift=-1: must be in [0, 16] pixels"),
        ("cameras=none", "env.camera=null: a camera policy needs a camera"),
        ("env.control.mode=ee_delta", "it reads 49 state values, this env's privileged state has 45"),
    ],
)
def test_bad_distillation_input_is_one_line_before_any_worker(override, match, tmp_path, train_cfg):
    from rlgrasp.algos.dagger.algorithm import distill
    from rlgrasp.config import ConfigError

    with pytest.raises((ConfigError, CheckpointError, FileNotFoundError)) as info:
        distill(train_cfg(*SMALL_DISTILL, override))
    message = str(info.value)
    assert match in message and "\n" not in message, message
