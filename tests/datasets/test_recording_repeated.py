"""Series whose time repeats a stamp (a bag's IMU often does): an error that names --lenient,
and under --lenient the repeating rows dropped and counted, in every reader that checks times."""

import numpy as np
import pytest

from eas_vo.datasets.ecd import EcdConfig, EcdFolderDataset
from eas_vo.errors import DataError, DataWarnings
from eas_vo.io.tables import check_increasing
from helpers import known_sequence


def test_a_repeated_time_is_refused_strictly_and_dropped_and_counted_leniently():
    t = np.array([0.0, 0.1, 0.1, 0.1, 0.2, 0.3, 0.3])
    with pytest.raises(
        DataError,
        match=r"imu.txt:3: timestamp 0.100000000 repeats the previous row's \(3 such row\(s\); "
        r"--lenient drops them\)",
    ):
        check_increasing("imu.txt", t)
    warnings = DataWarnings()
    keep = check_increasing("imu.txt", t, warnings=warnings)
    np.testing.assert_array_equal(keep, [0, 1, 4, 5])
    assert warnings.lines() == ["imu.txt: 3 dropped: repeated timestamp (first at line 3)"]
    with pytest.raises(DataError, match="does not increase"):  # a time going back stays an error
        check_increasing("imu.txt", np.array([0.0, 0.2, 0.1]), warnings=DataWarnings())


def test_an_ecd_imu_and_ground_truth_with_a_repeated_stamp(tmp_path):
    seq = known_sequence(tmp_path / "seq")
    for name in ("imu.txt", "groundtruth.txt"):
        lines = (seq / name).read_text().splitlines(keepends=True)
        (seq / name).write_text("".join(lines[:5] + [lines[4]] + lines[5:]))  # line 6 repeats line 5
    with pytest.raises(DataError, match=r"groundtruth.txt:6: timestamp .* repeats .*--lenient drops them"):
        EcdFolderDataset(str(seq))
    lenient = EcdFolderDataset(str(seq), EcdConfig(lenient=True))
    strict = EcdFolderDataset(str(known_sequence(tmp_path / "plain")))
    np.testing.assert_array_equal(lenient.imu.t, strict.imu.t)
    np.testing.assert_array_equal(lenient.ground_truth.q_w_c, strict.ground_truth.q_w_c)
    assert [line for line in lenient.data_warnings() if "repeated" in line] == [
        f"{seq / 'groundtruth.txt'}: 1 dropped: repeated timestamp (first at line 6)",
        f"{seq / 'imu.txt'}: 1 dropped: repeated timestamp (first at line 6)",
    ]
