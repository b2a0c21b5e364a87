"""An ECD folder's text files as editors leave them (a byte-order mark, CRLF line ends) read as
the plain files do; its two calibration files, calib.txt and camchain.yaml, are used only if
they agree."""

import numpy as np
import pytest

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.errors import DataError
from helpers import known_sequence

TEXT_FILES = ("images.txt", "events.txt", "imu.txt", "groundtruth.txt", "calib.txt")


@pytest.fixture
def folder(tmp_path):
    return known_sequence(tmp_path / "seq")


def test_a_byte_order_mark_and_crlf_line_ends_read_as_plain_text(folder, tmp_path):
    plain = EcdFolderDataset(str(known_sequence(tmp_path / "plain")))
    for name in TEXT_FILES:
        (folder / name).write_bytes(b"\xef\xbb\xbf" + (folder / name).read_bytes().replace(b"\n", b"\r\n"))
    edited = EcdFolderDataset(str(folder))
    np.testing.assert_array_equal(edited.frame_times(), plain.frame_times())
    np.testing.assert_array_equal(edited.events(), plain.events())
    np.testing.assert_array_equal(edited.imu.gyro, plain.imu.gyro)
    np.testing.assert_array_equal(edited.ground_truth.t, plain.ground_truth.t)
    np.testing.assert_array_equal(edited.camera.K, plain.camera.K)


def _camchain(fx, fy, cx, cy, dist) -> str:
    """cam0 of a kalibr camchain: a radial-tangential camera of the folder's 346x260 sensor."""
    return (
        f"cam0:\n  camera_model: pinhole\n  intrinsics: [{fx}, {fy}, {cx}, {cy}]\n  distortion_model: radtan\n"
        f"  distortion_coeffs: [{', '.join(map(str, dist))}]\n  resolution: [346, 260]\n"
    )


def test_calib_txt_and_a_camchain_that_disagree_are_refused_naming_both(folder):
    fx, fy, cx, cy, *dist = (float(v) for v in (folder / "calib.txt").read_text().split())
    (folder / "camchain.yaml").write_text(_camchain(fx, fy, cx, cy, dist[:4]))  # the same camera (k3 = 0): read
    assert EcdFolderDataset(str(folder)).camera.K[0, 0] == fx and dist[4] == 0
    (folder / "camchain.yaml").write_text(_camchain(fx * 0.75, fy, cx, cy, dist[:4]))
    with pytest.raises(
        DataError,
        match=rf"calib.txt and .*camchain.yaml: two calibrations of the camera that differ \(fx "
        rf"{fx:g} against {fx * 0.75:g}\); remove the wrong one, or choose one with "
        r"--set dataset.calibration=FILE",
    ):
        EcdFolderDataset(str(folder))
    (folder / "camchain.yaml").write_text(_camchain(fx, fy, cx, cy, [dist[0] + 0.05, *dist[1:4]]))
    with pytest.raises(DataError, match=rf"\(distortion {dist[0]:g} .* against {dist[0] + 0.05:g} "):
        EcdFolderDataset(str(folder))
