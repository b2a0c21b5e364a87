"""An ECD folder's text files as editors leave them (a byte-order mark, CRLF line ends) read as
the plain files do; its two calibration files, calib.txt and camchain.yaml, are used only if
they agree."""

import shutil

import numpy as np
import pytest

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.errors import DataError

TEXT_FILES = ("images.txt", "events.txt", "imu.txt", "groundtruth.txt", "calib.txt")


@pytest.fixture
def folder(short_sequence, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(short_sequence, seq, ignore=shutil.ignore_patterns(".*"))
    return seq


def test_a_byte_order_mark_and_crlf_line_ends_read_as_plain_text(short_sequence, folder):
    for name in TEXT_FILES:
        (folder / name).write_bytes(b"\xef\xbb\xbf" + (folder / name).read_bytes().replace(b"\n", b"\r\n"))
    edited, plain = EcdFolderDataset(str(folder)), EcdFolderDataset(str(short_sequence))
    np.testing.assert_array_equal(edited.frame_times(), plain.frame_times())
    np.testing.assert_array_equal(edited.events(), plain.events())
    np.testing.assert_array_equal(edited.imu.gyro, plain.imu.gyro)
    np.testing.assert_array_equal(edited.ground_truth.t, plain.ground_truth.t)
    np.testing.assert_array_equal(edited.camera.K, plain.camera.K)


def _camchain(fx: float, dist) -> str:
    return (f"cam0:\n  camera_model: pinhole\n  intrinsics: [{fx}, 200.0, 121.5, 89.0]\n  distortion_model: radtan\n"
            f"  distortion_coeffs: [{', '.join(map(str, dist))}]\n  resolution: [240, 180]\n")


def test_calib_txt_and_a_camchain_that_disagree_are_refused_naming_both(folder):
    assert (folder / "calib.txt").read_text().split() == ["200", "200", "121.5", "89", "-0.25", "0.08", "0.0002", "-0.0003", "0"]
    (folder / "camchain.yaml").write_text(_camchain(200.0, [-0.25, 0.08, 0.0002, -0.0003]))
    assert EcdFolderDataset(str(folder)).camera.K[0, 0] == 200.0  # the same camera: read
    (folder / "camchain.yaml").write_text(_camchain(150.0, [-0.25, 0.08, 0.0002, -0.0003]))
    with pytest.raises(DataError, match=r"calib.txt and .*camchain.yaml: two calibrations of the camera that differ \(fx 200 "
                                        r"against 150\); remove the wrong one, or choose one with --set dataset.calibration=FILE"):
        EcdFolderDataset(str(folder))
    (folder / "camchain.yaml").write_text(_camchain(200.0, [-0.2, 0.08, 0.0002, -0.0003]))
    with pytest.raises(DataError, match=r"\(distortion -0.25 0.08 0.0002 -0.0003 0 against -0.2 0.08 0.0002 -0.0003 0\)"):
        EcdFolderDataset(str(folder))
