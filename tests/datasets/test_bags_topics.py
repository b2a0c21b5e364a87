"""A bag's topics as the readers find them: a topic named but absent is refused with the
topics of its message type the bag does hold; an IMU repeating a stamp (as bags often do) is
refused naming --lenient, which drops and counts the repeats."""

import numpy as np
import pytest

from eas_vo.datasets.bags import BagConfig
from eas_vo.datasets.rosbag2 import Rosbag2Dataset, write_bag2
from eas_vo.errors import DataError
from eas_vo.types import ImuSeries, PoseSeries
from helpers import CAMERA, InMemoryDataset


@pytest.fixture(scope="module")
def vicon_bag(tmp_path_factory):
    """A 1 s ROS 2 bag with its poses on /vicon/davis and an IMU whose reading 5 repeats reading 4's stamp."""
    rng = np.random.default_rng(2)
    events = np.zeros(500, [("t", "<f8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])
    events["t"] = np.sort(rng.uniform(0, 1, 500))
    events["x"], events["y"], events["p"] = (
        rng.integers(0, 240, 500),
        rng.integers(0, 180, 500),
        rng.integers(0, 2, 500),
    )
    imu_t = np.arange(20) / 20.0
    imu_t[5] = imu_t[4]
    imu = ImuSeries(imu_t, rng.normal(size=(20, 3)), rng.normal(size=(20, 3)))
    poses = PoseSeries(np.arange(10) / 10.0, np.zeros((10, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (10, 1)))
    dataset = InMemoryDataset(CAMERA, np.arange(5) * 0.2, [np.zeros((180, 240), np.uint8)] * 5, events, imu, poses)
    path = tmp_path_factory.mktemp("bags") / "vicon"
    write_bag2(dataset, path, config=BagConfig(pose_topic="/vicon/davis"))
    return path


def test_a_named_topic_that_is_absent_is_refused_with_the_topics_of_its_type(vicon_bag):
    with pytest.raises(
        DataError,
        match=r"has no topic /optitrack/pose \(dataset.pose_topic\); its geometry_msgs/msg/"
        r"PoseStamped topic: /vicon/davis \(--set dataset.pose_topic=/vicon/davis\); it holds",
    ):
        Rosbag2Dataset(str(vicon_bag), BagConfig(pose_topic="/optitrack/pose", lenient=True))
    with pytest.raises(
        DataError, match=r"has no topic /dvs/gyro \(dataset.imu_topic\); its sensor_msgs/msg/Imu topic: /dvs/imu"
    ):
        Rosbag2Dataset(str(vicon_bag), BagConfig(imu_topic="/dvs/gyro", lenient=True))


def test_an_imu_repeating_a_stamp_is_refused_naming_lenient_which_drops_it(vicon_bag):
    with pytest.raises(DataError, match=r"/dvs/imu:5: timestamp .* repeats the previous row's .*--lenient drops them"):
        Rosbag2Dataset(str(vicon_bag))
    lenient = Rosbag2Dataset(str(vicon_bag), BagConfig(lenient=True))
    assert len(lenient.imu.t) == 19 and (np.diff(lenient.imu.t) > 0).all()
    assert lenient.ground_truth is not None and lenient.topic["pose_topic"] == "/vicon/davis"
    assert f"{vicon_bag}:/dvs/imu: 1 dropped: repeated timestamp (first at message 5)" in lenient.data_warnings()
