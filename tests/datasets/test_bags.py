"""What both bag readers share: CameraInfo -> CameraModel (calibration.camera_from_camera_info)
for each distortion model, at several sensor sizes, the refusals naming the topic and the
message, and ROS time."""

import numpy as np
import pytest

from eas_vo.datasets.bags import stamp_ns
from eas_vo.datasets.calibration import camera_from_camera_info
from eas_vo.datasets.recording import clock_origin_ns
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
    short = camera_from_camera_info(
        f"{WHERE}:0", width, height, K, [-0.3, 0.1], "plumb_bob"
    )  # k1 k2 only: the rest zero
    assert short.dist.tolist() == [-0.3, 0.1, 0.0, 0.0, 0.0]
    none = camera_from_camera_info(f"{WHERE}:0", width, height, K, [], "")  # a driver that leaves both empty
    assert none.model == "radtan" and not none.dist.any()
    fisheye = camera_from_camera_info(f"{WHERE}:0", width, height, K, [0.1, -0.02, 3e-3, -4e-4], "equidistant")
    assert fisheye.model == "equidistant" and fisheye.dist.tolist() == [0.1, -0.02, 3e-3, -4e-4]
    rational = camera_from_camera_info(
        f"{WHERE}:0", width, height, K, [-0.3, 0.1, 1e-3, -2e-3, 0.01, 0, 0, 0], "rational_polynomial"
    )
    assert rational.model == "radtan" and rational.dist.tolist() == radtan.dist.tolist()


@pytest.mark.parametrize(
    "model, D, message",
    [
        (
            "rational_polynomial",
            [-0.3, 0.1, 0, 0, 0.01, 0.2, 0, 0],
            r"K/D: 8 radial-tangential distortion coefficients: k1 k2 p1 p2 \[k3\] are read",
        ),
        ("plumb_bob", [0.1] * 6, r"K/D: 6 radial-tangential distortion coefficients"),
        (
            "equidistant",
            [0.1] * 5,
            r"K/D: the equidistant lens model takes 4 distortion coefficients \(k1 k2 k3 k4\), found 5$",
        ),
        ("equidistant", [11.0, 0, 0, 0], r"K/D: distortion k1 k2 k3 k4 = 11 0 0 0 out of range"),
        ("plumb_bob", [20.0], r"K/D: distortion k1 k2 p1 p2 k3 = 20 0 0 0 0 out of range"),
        ("fov", [0.9], r"distortion_model: 'fov' is not read"),
        ("plumb_bob", [float("nan")], r"K/D: intrinsics and distortion must be finite"),
    ],
)
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


def _with_camera_info_of(bag, out, width, height, images=True):
    """A copy of `bag` whose CameraInfo is for a width x height sensor (K scaled to it), and
    without its images unless `images`."""
    from rosbags.rosbag1 import Reader, Writer

    from eas_vo.datasets.rosbag import typestore

    store = typestore()
    with Reader(bag) as reader, Writer(out) as writer:
        kept = [c for c in reader.connections if images or c.msgtype != "sensor_msgs/msg/Image"]
        connections = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in kept}
        for connection, timestamp, raw in reader.messages(connections=kept):
            if connection.msgtype == "sensor_msgs/msg/CameraInfo":
                msg = store.deserialize_ros1(raw, connection.msgtype)
                K = msg.K.reshape(3, 3).copy()
                K[0] *= width / msg.width
                K[1] *= height / msg.height
                msg.width, msg.height, msg.K = width, height, K.ravel()
                raw = store.serialize_ros1(msg, connection.msgtype)
            writer.write(connections[connection.id], timestamp, raw)
    return out


@pytest.fixture(scope="module")
def sequence_bag(short_sequence, tmp_path_factory):
    """The short simulated sequence (240x180) as a ROS 1 bag."""
    from eas_vo.datasets.rosbag import write_bag
    from eas_vo.registry import open_dataset

    path = tmp_path_factory.mktemp("bag") / "seq.bag"
    write_bag(open_dataset(str(short_sequence)), path)
    return path


@pytest.mark.parametrize("images", [True, False], ids=["frames", "events_only"])
def test_a_camera_info_of_another_sensor_than_the_datas_is_refused(short_sequence, sequence_bag, tmp_path, images):
    """A 640x480 CameraInfo in a bag of 240x180 frames and events (their messages state
    240x180) is refused naming both sizes, with frames or without; a calibration file of the
    data's size is taken instead of it."""
    from eas_vo.datasets.rosbag import BagConfig, RosbagDataset

    bag = _with_camera_info_of(sequence_bag, tmp_path / "vga.bag", 640, 480, images)
    topic = "/dvs/image_raw" if images else "/dvs/events"
    seen = "its frames are" if images else "its event messages state a sensor of"
    with pytest.raises(DataError, match=rf"^{bag}:{topic}:0: the calibration is for 640x480 px, {seen} 240x180$"):
        RosbagDataset(bag)
    camera = RosbagDataset(bag, BagConfig(calibration=str(short_sequence / "calib.txt"))).camera
    assert (camera.width, camera.height) == (240, 180)
