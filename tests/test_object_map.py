"""The object-map term: one keypoint of the encoder trained onto where the object's pixels are."""

from __future__ import annotations

import math
import runpy
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from rlgrasp.algos.sac import SAC
from rlgrasp.compose import compose_train
from rlgrasp.config import ConfigError
from rlgrasp.models.cnn import vision_net
from rlgrasp.train.parts import build_parts
from rlgrasp.vision.object_map import cells_on_map, map_window

SMALL = [
    "experiment=grasp_vision_sac",
    "logger=none",
    "collector=single",
    "collector.envs_per_worker=2",
    "collector.steps_per_env=32",
    "total_frames=256",
    "model.channels=[4,4,4]",
    "model.image_features=8",
    "algo.replay.buffer_frames=1024",
    "algo.replay.learning_starts=0",
]
MAP = ["model=cnn_keypoints", "+env.camera.object_cells=4", "algo.terms.object_map.coeff=1"]


def _sac(tmp_path: Path, *overrides: str) -> SAC:
    cfg = compose_train([*SMALL, f"paths.output_dir={tmp_path}", *overrides])
    torch.manual_seed(0)
    return SAC(cfg, build_parts(cfg), torch.device("cpu"))


def test_a_map_cell_sits_where_the_convolutions_put_its_receptive_field() -> None:
    assert map_window((8, 3, 3), (4, 1, 1)) == (11.5, 4)  # cnn_keypoints: an 11 x 11 map of a 64-pixel image
    assert map_window((8, 4, 3), (4, 2, 1)) == (17.5, 8)  # the flat encoder's geometry


def test_the_object_cells_land_on_the_map_cells_over_their_pixels() -> None:
    cells = torch.zeros(2, 64)
    cells[0, 3 * 8 + 4] = 1.0  # rows 24-31, columns 32-39 of a 64-pixel image
    cells[1, 0] = 1.0  # rows and columns 0-7: left of the first map cell's window, which starts at 10
    on_map = cells_on_map(cells, 64, 11, 11.5, 4).reshape(2, 11, 11)
    assert on_map[0].sum() * 16 == 64  # every object pixel inside the window, counted once
    # Map cell (i, j) averages rows 10 + 4i to 13 + 4i and the same columns: (4, 6) lies inside the
    # object's pixels, (3, 6) and (5, 6) half over them, (3, 5) a quarter.
    assert on_map[0, 4, 6] == 1.0 and on_map[0, 3, 6] == 0.5 and on_map[0, 5, 6] == 0.5
    assert on_map[0, 3, 5] == 0.25 and on_map[0, 4, 5] == 0.5
    assert on_map[1].sum() == 0  # out of the map's window: nothing to point at


def test_a_uniform_map_costs_the_log_of_its_cells_and_an_image_without_the_object_costs_nothing(
    tmp_path: Path,
) -> None:
    sac = _sac(tmp_path, *MAP)
    term = sac.object_map
    n, cells = 6, 16
    start, stop = sac.parts.spec["privileged_parts"]["object_cells"]
    privileged = torch.zeros(n, sac.parts.spec["privileged_dim"])
    privileged[:3, start + 5] = 1.0  # three images show the object in cell (1, 1); three show none
    batch = TensorDict({"privileged": privileged}, [n])
    term.kept = [torch.zeros(n, 4, 11, 11)]
    assert term.loss(batch).item() == pytest.approx(math.log(121))
    assert term.kept == []  # let go once read
    term.kept = [torch.zeros(3, 4, 11, 11)]
    assert term.loss(batch[3:]).item() == 0.0
    assert stop - start == cells


def _camera_batch(sac: SAC, n: int) -> TensorDict:
    spec = sac.parts.spec
    start, _ = spec["privileged_parts"]["object_cells"]
    obs_dim, act_dim = spec["obs_dim"], len(spec["action_low"])
    false = torch.zeros(n, 1, dtype=torch.bool)
    td = {
        "observation": torch.randn(n, obs_dim),
        "action": torch.rand(n, act_dim) * 2 - 1,
        "sample_log_prob": torch.zeros(n),
        "next": {
            "observation": torch.randn(n, obs_dim),
            "reward": torch.rand(n, 1),
            "done": false,
            "terminated": false,
        },
    }
    for part in (td, td["next"]):
        part["depth"] = torch.rand(n, *spec["images"]["depth"])
        part["privileged"] = torch.zeros(n, spec["privileged_dim"])
        part["privileged"][:, start + 6] = 1.0
    return TensorDict(td, [n]).unsqueeze(0)


def test_the_term_trains_the_encoder_through_its_first_keypoint_map(tmp_path: Path) -> None:
    sac = _sac(tmp_path, *MAP, "algo.optim.utd_ratio=0.25")
    convs = vision_net(sac.actor).encoders["depth"].conv
    before = convs[0].weight.detach().clone()
    sac.update(_camera_batch(sac, 32), 0)
    metrics = sac.update(_camera_batch(sac, 32), 0)
    assert 0 < metrics["loss_object_map"] < math.log(121) + 1
    assert not torch.equal(before, convs[0].weight)
    assert "privileged" in sac.transition_keys  # the label is kept with each transition


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["+env.camera.object_cells=4", "algo.terms.object_map.coeff=1"], "needs the keypoint encoder"),
        (["model=cnn_keypoints", "algo.terms.object_map.coeff=1"], r"\+env.camera.object_cells=8"),
    ],
)
def test_the_term_without_keypoints_or_object_cells_is_refused_in_one_line(
    tmp_path: Path, overrides: list[str], message: str
) -> None:
    with pytest.raises(ConfigError, match=f"^algo.terms.object_map.coeff: .*{message}"):
        _sac(tmp_path, *overrides)


def test_locate_object_scores_a_map_against_the_object_and_skips_images_without_it() -> None:
    """benchmarks/locate_object.py's score: ln 121 for a map that says nothing, the peak on the
    object's map cell when the map says it, and no object, no score."""
    score = runpy.run_path(str(Path(__file__).resolve().parents[1] / "benchmarks" / "locate_object.py"))
    cells = torch.zeros(3, 64)
    cells[:2, 3 * 8 + 4] = 1.0  # the object on map cells (3-5, 5-7), the middle one (4, 6) whole
    maps = torch.zeros(3, 4, 11, 11)
    maps[1, 0, 3:6, 5:8] = 2.0  # the second image's map points at the object, its peak in the middle
    maps[1, 0, 4, 6] = 3.0
    cross, entropy, peak_on_object, shows = score["_cross_entropy"](
        maps, cells, map_window((8, 3, 3), (4, 1, 1))
    )
    assert shows.tolist() == [True, True, False]
    assert cross[0].item() == pytest.approx(math.log(121))
    assert cross[1] < cross[0] and entropy[1] < cross[1]
    assert peak_on_object[1] and not peak_on_object[0]
