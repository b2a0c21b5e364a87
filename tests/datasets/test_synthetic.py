"""The synthetic dataset's camera: presets, any sensor size (same field of view), any lens."""

import math
from pathlib import Path

import pytest

from eas_vo.config import build
from eas_vo.datasets.simulator.generate import SENSORS, SimCamera
from eas_vo.datasets.synthetic import SyntheticConfig
from eas_vo.errors import ConfigError


def test_the_default_camera_is_the_davis240_every_earlier_sequence_had():
    assert SyntheticConfig().camera() == SimCamera() == SENSORS["davis240"]


def test_another_sensor_size_keeps_the_diagonal_field_of_view_and_the_lens():
    base = SENSORS["davis240"]
    for width, height in ((346, 260), (640, 480), (1280, 720)):
        cam = SyntheticConfig(width=width, height=height).camera()
        assert (cam.width, cam.height, cam.lens, cam.dist) == (width, height, base.lens, base.dist)
        assert math.hypot(width, height) / cam.fx == pytest.approx(
            math.hypot(base.width, base.height) / base.fx, rel=1e-12
        )
        assert (cam.cx + 0.5) / width == pytest.approx((base.cx + 0.5) / base.width, rel=1e-12)
        assert (cam.cy + 0.5) / height == pytest.approx((base.cy + 0.5) / base.height, rel=1e-12)
    assert SyntheticConfig(width=346, height=260, focal_px=300.0).camera().fx == 300.0


def test_the_davis346_preset_and_a_lens_of_ones_own():
    assert SyntheticConfig(sensor="davis346").camera() == SENSORS["davis346"]
    assert SENSORS["davis346"].lens == "equidistant" and (SENSORS["davis346"].width, SENSORS["davis346"].height) == (
        346,
        260,
    )
    pinhole = SyntheticConfig(sensor="davis346", lens="radtan").camera()
    assert pinhole.lens == "radtan" and pinhole.dist == (0.0,) * 5  # another lens: no coefficients unless given
    fisheye = build(SyntheticConfig, {"lens": "equidistant", "dist": [0.1, 0, -0.01, 0]}, "dataset").camera()
    assert (fisheye.width, fisheye.lens, fisheye.dist) == (240, "equidistant", (0.1, 0.0, -0.01, 0.0))


@pytest.mark.parametrize(
    "values, says",
    [
        ({"sensor": "davis640"}, "dataset.sensor = 'davis640'; allowed: davis240, davis346"),
        ({"lens": "fisheye"}, "dataset.lens = 'fisheye'; allowed: , radtan, equidistant"),
        (
            {"lens": "equidistant", "dist": [0.1, 0.0]},
            r"dataset.dist = \[0.1, 0.0\]: the equidistant lens takes 4 finite numbers \(k1 k2 k3 k4\)",
        ),
        ({"dist": [0.1, 0.0, 0.0, 0.0]}, r"the radtan lens takes 5 finite numbers \(k1 k2 p1 p2 k3\)"),
        ({"dist": [0.1, 0.0, 0.0, 0.0, "x"]}, "the radtan lens takes 5 finite numbers"),
        (
            {"width": 346, "height": 260, "focal_px": 1.0},
            "dataset.focal_px: the camera is impossible: focal lengths fx = 1, fy = 1 px",
        ),
        ({"dist": [0.1, 0.0, 3.0, 0.0, 0.0]}, "dataset.dist: the camera is impossible: distortion k1 k2 p1 p2 k3"),
        ({"width": -1}, "dataset.width = -1 is out of range"),
    ],
)
def test_an_impossible_camera_is_one_line_naming_the_key(values, says):
    with pytest.raises(ConfigError, match=says):
        build(SyntheticConfig, values, "dataset")


def test_light_speed_and_translation_scale_the_presets_own():
    """The walk's preset is lit 100 times and translates 10 times the default's; a dataset value
    scales that (1: the preset as it is; illumination 0.01 on the walk is the dim room's light)."""
    from eas_vo.datasets.synthetic import PRESETS

    walk = SyntheticConfig().applied_to(PRESETS["walk"])
    assert (walk.illumination, walk.translation_scale, walk.speed) == (100.0, 10.0, 1.0)
    dim = SyntheticConfig(illumination=0.01, translation_scale=0.5, speed=2.0).applied_to(PRESETS["walk"])
    assert (dim.illumination, dim.translation_scale, dim.speed) == (pytest.approx(1.0), 5.0, 2.0)
    assert SyntheticConfig().applied_to(PRESETS["default"]).fingerprint() == PRESETS["default"].fingerprint()


def test_a_simulation_finished_second_leaves_the_first_in_place_and_replaces_a_half_folder(tmp_path):
    """Two processes simulating the same sequence (two runs, two test workers) into one cache:
    the one that finishes second must not remove the folder the first put there, which the
    first may already be reading; a folder without images.txt (a crash's) is replaced."""
    from eas_vo.datasets.synthetic import _put_in_place

    def simulated(name: str, complete: bool = True) -> Path:
        folder = tmp_path / name
        folder.mkdir()
        (folder / "events.txt").write_text(name)
        if complete:
            (folder / "images.txt").write_text(name)
        return folder

    folder = tmp_path / "default-abc"
    _put_in_place(simulated("first"), folder)
    reading = (folder / "events.txt").open()
    second = simulated("second")
    _put_in_place(second, folder)
    assert reading.read() == "first" and (folder / "events.txt").read_text() == "first"
    reading.close()
    assert second.exists()  # the caller removes its own copy

    half = tmp_path / "default-def"
    simulated("crashed", complete=False).rename(half)
    _put_in_place(simulated("third"), half)
    assert (half / "images.txt").read_text() == "third"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["default-abc", "default-def", "second"]
