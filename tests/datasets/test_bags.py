"""What both bag readers share: CameraInfo -> CameraModel (calibration.camera_from_camera_info)
for each distortion model, at several sensor sizes, the refusals naming the topic and the
message, and ROS time."""

import numpy as np
import pytest

from eas_vo.datasets.bags import stamp_ns
from eas_vo.datasets.recording import clock_origin_ns
from eas_vo.datasets.calibration import camera_from_camera_info
from eas_vo.errors import DataError

WHERE = "bag.db3:/cam/info"


def K_of(width, height, focal_widths=1.2):
    f = focal_widths * width
    return [f, 0.0, width / 2, 0.0, 1.01 * f, height / 2, 0.0, 0.0, 1.0]


@pytest.mark.parametrize("size", [(240, 180), (346, 260), (1280, 720)])
def test_plumb_bob_and_equidistant(size):
    width, height = size
    K = K_of(width, height)
    radtan = camera_from_camera_info(f"{WHERE}:0", width, height, K, [-0.3, 0.1, 1e-3, -2e-3, 0.01], "plumb_bob")
    assert radtan.model == "radtan" and radtan.dist.tolist() == [-0.3, 0.1, 1e-3, -2e-3, 0.01]
    assert radtan.K.tolist() == [[K[0], 0, K[2]], [0, K[4], K[5]], [0, 0, 1]]
    assert (radtan.width, radtan.height) == size
    short = camera_from_camera_info(f"{WHERE}:0", width, height, K, [-0.3, 0.1], "plumb_bob")  # k1 k2 only: the rest zero
    assert short.dist.tolist() == [-0.3, 0.1, 0.0, 0.0, 0.0]
    none = camera_from_camera_info(f"{WHERE}:0", width, height, K, [], "")  # a driver that leaves both empty
    assert none.model == "radtan" and not none.dist.any()
    fisheye = camera_from_camera_info(f"{WHERE}:0", width, height, K, [0.1, -0.02, 3e-3, -4e-4], "equidistant")
    assert fisheye.model == "equidistant" and fisheye.dist.tolist() == [0.1, -0.02, 3e-3, -4e-4]
    rational = camera_from_camera_info(f"{WHERE}:0", width, height, K, [-0.3, 0.1, 1e-3, -2e-3, 0.01, 0, 0, 0], "rational_polynomial")
    assert rational.model == "radtan" and rational.dist.tolist() == radtan.dist.tolist()


@pytest.mark.parametrize("model, D, message", [
    ("rational_polynomial", [-0.3, 0.1, 0, 0, 0.01, 0.2, 0, 0], r"K/D: 8 radial-tangential distortion coefficients: k1 k2 p1 p2 \[k3\] are read"),
    ("plumb_bob", [0.1] * 6, r"K/D: 6 radial-tangential distortion coefficients"),
    ("equidistant", [0.1] * 5, r"K/D: the equidistant lens model takes 4 distortion coefficients \(k1 k2 k3 k4\), found 5$"),
    ("equidistant", [11.0, 0, 0, 0], r"K/D: distortion k1 k2 k3 k4 = 11 0 0 0 out of range"),
    ("plumb_bob", [20.0], r"K/D: distortion k1 k2 p1 p2 k3 = 20 0 0 0 0 out of range"),
    ("fov", [0.9], r"distortion_model: 'fov' is not read"),
    ("plumb_bob", [float("nan")], r"K/D: intrinsics and distortion must be finite"),
])
def test_refusals_name_topic_and_message(model, D, message):
    with pytest.raises(DataError, match=rf"^{WHERE}:7: {message}") as info:
        camera_from_camera_info(f"{WHERE}:7", 640, 480, K_of(640, 480), D, model)
    assert "\n" not in str(info.value)


def test_intrinsics_of_another_sensor_are_refused():
    with pytest.raises(DataError, match=r":3: K/D: principal point cx = 120, cy = 90 px lies off the 100x80 sensor"):
        camera_from_camera_info(f"{WHERE}:3", 100, 80, K_of(240, 180, 0.5), [], "plumb_bob")


def test_stamps_are_integer_nanoseconds_read_after_the_clock_origin():
    """ROS time stays integer ns; a Unix-time clock is read after its first whole second, so
    relative times are the nearest doubles to the stamps' own digits (as float64 seconds at 1.4e9
    they would keep only about 0.24 us)."""
    assert stamp_ns(1403636580, 13555) == 1403636580_000013555
    assert stamp_ns(np.array([0, 12]), np.array([1, 345_678_901])).tolist() == [1, 12_345_678_901]
    assert clock_origin_ns(12_345_678_901) == 0 and clock_origin_ns(-5) == 0  # a clock near zero is read as it is
    origin = clock_origin_ns(1403636580_000013555)
    assert origin == 1403636580 * 10**9
    assert (1403636580_000013555 - origin) / 1e9 == 1.3555e-05
