"""benchmarks/camera_grid.py, the docs' pictures of what each camera sees: on a tiny grid (one preset,
one camera, 16x16 pixels) it writes a PNG laid out as its labels and images need."""

import runpy
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]


def test_the_camera_grid_writes_a_labelled_png_of_the_expected_size(tmp_path: Path, capsys) -> None:
    script = runpy.run_path(str(ROOT / "benchmarks" / "camera_grid.py"))
    out = tmp_path / "grid.png"
    argv = [
        "--presets",
        "none",
        "--cameras",
        "wrist_depth",
        "--size",
        "16",
        "--scale",
        "2",
        "--out",
        str(out),
    ]
    assert script["main"](argv) == out
    pad, font = script["PAD"], script["FONT_SIZE"]
    cell = 16 * 2 + pad
    with Image.open(out) as image:
        assert image.size == (script["label_width"](["none"]) + cell, font + 2 * pad + cell)
        pixels = np.asarray(image.convert("RGB"))
    assert pixels.std() > 0  # something was drawn: labels and a depth image, not a blank sheet
    printed = capsys.readouterr().out
    assert "python benchmarks/camera_grid.py --presets none" in printed and str(out) in printed


def test_depth_pictures_are_grey_normalized_per_image_with_missing_pixels_black() -> None:
    depth_picture = runpy.run_path(str(ROOT / "benchmarks" / "camera_grid.py"))["depth_picture"]
    picture = depth_picture(np.array([[0.0, 0.3], [0.31, 0.5]], np.float32))
    assert picture.shape == (2, 2, 3) and (picture[..., 0] == picture[..., 2]).all()
    assert picture[0, 0, 0] == 0 and picture[0, 1, 0] < picture[1, 0, 0] < picture[1, 1, 0] == 255
