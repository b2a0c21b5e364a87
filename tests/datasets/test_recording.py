"""What the recording readers share: sampling event-only streams, reading poses, the calibration
and ground-truth files every reader takes."""

import shutil

import numpy as np
import pytest

from eas_vo import registry
from eas_vo.datasets.recording import event_sample_times
from eas_vo.datasets.rosbag import write_bag
from eas_vo.datasets.rosbag2 import write_bag2
from eas_vo.io.tum import pose_series
from eas_vo.registry import open_dataset


def test_event_sample_times_by_rate_and_by_count():
    t = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(event_sample_times(t, 10.0, 0), np.arange(0, 1.0, 0.1))
    np.testing.assert_array_equal(event_sample_times(t, 10.0, 250), t[::250])
    assert len(event_sample_times(t[:0], 10.0, 0)) == 0


def test_poses_written_with_nine_decimals_read_back_as_written_and_others_are_normalised():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    text = "".join(
        " ".join(f"{v:.9f}" for v in row) + "\n" for row in np.column_stack([np.arange(500.0), np.zeros((500, 3)), q])
    )
    table = np.loadtxt(text.splitlines())
    assert np.abs(np.linalg.norm(table[:, 4:], axis=1) - 1).max() > 1e-12  # the text is not unit to the last bit
    np.testing.assert_array_equal(pose_series("gt", table).q_w_c, table[:, 4:])
    table[:, 4:] *= 1.001
    np.testing.assert_allclose(np.linalg.norm(pose_series("gt", table).q_w_c, axis=1), 1.0, rtol=0, atol=1e-15)


WRITERS = {
    "ecd": lambda ds, path: path.parent / "seq",
    "rosbag": lambda ds, path: (write_bag(ds, path.with_suffix(".bag")), path.with_suffix(".bag"))[1],
    "rosbag2": lambda ds, path: (write_bag2(ds, path, "mcap"), path)[1],
}


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_every_reader_takes_a_calibration_and_a_ground_truth_file(short_sequence, tmp_path, fmt):
    """dataset.calibration replaces the recording's own intrinsics (a bag's CameraInfo, an ECD
    calib.txt), dataset.ground_truth its poses, with ground_truth_time_offset_s added."""
    shutil.copytree(short_sequence, tmp_path / "seq")
    base = open_dataset(str(tmp_path / "seq"))
    path = WRITERS[fmt](base, tmp_path / "recording")
    K = base.camera.K
    calib = tmp_path / "other_calib.txt"
    calib.write_text(f"{K[0, 0] * 1.1} {K[1, 1] * 1.1} {K[0, 2] - 3} {K[1, 2] + 2} -0.1 0.01 0 0 0\n")
    tum = tmp_path / "poses.tum"
    tum.write_text("0.0 0 0 0 0 0 0 1\n5.0 1 0 0 0 0 0.6 0.8\n")
    config = registry.resolve_dataset(str(path))[0].Config(
        calibration=str(calib), ground_truth=str(tum), ground_truth_time_offset_s=-2.5
    )
    ds = open_dataset(str(path), config)
    np.testing.assert_allclose(
        ds.camera.K, [[K[0, 0] * 1.1, 0, K[0, 2] - 3], [0, K[1, 1] * 1.1, K[1, 2] + 2], [0, 0, 1]]
    )
    np.testing.assert_allclose(ds.camera.dist, [-0.1, 0.01, 0, 0, 0])
    np.testing.assert_array_equal(ds.ground_truth.t, [-2.5, 2.5])
    np.testing.assert_array_equal(ds.ground_truth.q_w_c[1], [0, 0, 0.6, 0.8])
