"""Every reader's work is bounded by its input: a small recording written by each format's
writer (ECD folder and zip, MVSEC HDF5, ROS 1 bag, ROS 2 sqlite3 and mcap bags), seeded single
bit flips anywhere in its files, each read whole in a child process: a one-line error or a
successful read within seconds, never a spin, a crash or a traceback. (AEDAT4's sweep is in
test_aedat4.py, beside its writer.)"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from eas_vo.camera import CameraModel
from eas_vo.datasets.ecd import write_ecd_folder
from eas_vo.types import EVENT_DTYPE, ImuSeries, PoseSeries
from helpers import InMemoryDataset, flipped_copies, read_each_bounded, seeded_flips, write_mvsec

WIDTH, HEIGHT = 40, 30  # not the DAVIS240's
FLIPS = 30  # per format: about 60 s of reads in all


def tiny() -> InMemoryDataset:
    """Four frames, 400 events, IMU and ground truth over 0.1 s, at Unix time (as cameras stamp)."""
    rng = np.random.default_rng(4)
    t0 = 1_700_000_000.0
    camera = CameraModel(WIDTH, HEIGHT, np.array([[36.0, 0, WIDTH / 2], [0, 36.0, HEIGHT / 2], [0, 0, 1]]))
    times = t0 + np.array([0.01, 0.04, 0.07, 0.1])
    frames = [rng.integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8) for _ in times]
    events = np.zeros(400, EVENT_DTYPE)
    events["t"] = t0 + np.sort(rng.uniform(0, 0.1, 400))
    events["x"], events["y"], events["p"] = (
        rng.integers(0, WIDTH, 400),
        rng.integers(0, HEIGHT, 400),
        rng.integers(0, 2, 400),
    )
    t = t0 + np.linspace(0, 0.1, 21)
    imu = ImuSeries(t, np.tile([0.0, 0.0, 9.81], (21, 1)), np.tile([0.1, 0.0, 0.0], (21, 1)))
    return InMemoryDataset(
        camera, times, frames, events, imu, PoseSeries(t, np.zeros((21, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (21, 1)))
    )


def write_all(root):
    """{format: (the written location, --set assignments to read it)}."""
    from eas_vo.datasets.rosbag import write_bag
    from eas_vo.datasets.rosbag2 import write_bag2

    data = tiny()
    ecd = root / "ecd"
    write_ecd_folder(ecd, data.camera, data.frame_times(), data._frames, data.events(), data.ground_truth, data.imu)
    shutil.make_archive(str(root / "zip" / "ecd"), "zip", ecd)
    calibration = [f"dataset.calibration={ecd / 'calib.txt'}"]
    write_bag(data, root / "rec.bag", events_per_message=100)
    write_bag2(data, root / "sqlite3", "sqlite3", events_per_message=100)
    write_bag2(data, root / "mcap", "mcap", events_per_message=100)
    return {
        "ecd": (ecd, []),
        "ecd-zip": (root / "zip" / "ecd.zip", []),
        "mvsec": (write_mvsec(root / "mvsec", data), calibration),
        "rosbag": (root / "rec.bag", []),
        "rosbag2-sqlite3": (root / "sqlite3", []),
        "rosbag2-mcap": (root / "mcap", []),
    }


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    return write_all(tmp_path_factory.mktemp("formats"))


@pytest.mark.parametrize("fmt", ["ecd", "ecd-zip", "mvsec", "rosbag", "rosbag2-sqlite3", "rosbag2-mcap"])
def test_a_flipped_bit_is_a_one_line_error_or_a_read_within_seconds(written, fmt, tmp_path):
    location, assignments = written[fmt]
    copies = flipped_copies(location, tmp_path, seeded_flips(location, FLIPS, seed=sum(map(ord, fmt))))
    outcomes = read_each_bounded([location, *copies], assignments)
    assert outcomes[str(location)] == "ok"  # the writer's own file reads
    for copy in copies:
        outcome = outcomes[str(copy)]
        assert outcome == "ok" or str(copy.parent) in outcome, (copy, outcome)  # an error names the damaged file
