"""The one TUM reader and writer: a round trip exact to the written digits (a Unix-time clock
too), and one error behaviour, naming the file and its line, for every use (ground truth,
eas-vo's own trajectories, other tools' estimates)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.errors import DataError, DataWarnings
from eas_vo.io.tum import format_tum, parse_tum, read_tum

UNIX_NS = 1_700_000_000_123_456_789


@pytest.mark.parametrize("origin_ns", [0, UNIX_NS])
def test_written_poses_read_back(origin_ns):
    """From a clock at 0 every figure comes back to its written digits; from a Unix-time clock the
    times are parsed as float64 before the origin is taken off, which keeps them to float64's
    resolution at 1.7e9 s (0.24 us)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.05, 30))
    R = Rotation.from_rotvec(rng.normal(0, 0.5, (30, 3))).as_matrix()
    p = rng.normal(size=(30, 3))
    text = format_tum(t, p, R, origin_ns)
    assert text.split()[0].startswith("1700000000." if origin_ns else "0.")
    back = parse_tum(text.encode(), "x", origin_ns=origin_ns)
    np.testing.assert_allclose(back.t, t, rtol=0, atol=2.5e-7 if origin_ns else 5e-10)
    np.testing.assert_allclose(back.p_w_c, p, rtol=0, atol=5e-10)
    np.testing.assert_allclose(back.q_w_c, Rotation.from_matrix(R).as_quat(), rtol=0, atol=5e-13)


@pytest.mark.parametrize(
    "rows, line, says",
    [
        (["1 0 0 0 0 0 0 1", "0.5 0 0 0 0 0 0 1"], 2, "timestamp 0.500000000 does not increase"),
        (["1 0 0 0 0 0 0 1", "# a comment", "1 0 0 0 0 0 0 1"], 3, "repeats the previous row's"),
        (["1 0 0 0 0 0 0 1", "2 0 0 0 0 0 0.5 0.5"], 2, "quaternion norm 0.707 is not 1"),
        (["1 0 0 0 0 0 0 1", "2 0 0 0 0 0 1"], 2, "expected 8 columns"),
        (["1 0 0 0 0 0 0 1", "2 0 0 0 nan 0 0 1"], 2, "NaN or infinite"),
    ],
)
def test_every_use_refuses_a_bad_row_naming_its_file_and_line(tmp_path, rows, line, says):
    path = tmp_path / "poses.tum"
    path.write_text("\n".join(rows) + "\n")
    for kwargs in ({}, {"min_poses": 2, "what": "ground truth"}):
        with pytest.raises(DataError, match=f"poses.tum:{line}: .*{says}"):
            read_tum(path, **kwargs)


def test_a_repeated_time_is_dropped_and_counted_when_lenient_and_kept_in_eas_vos_own_files():
    text = b"1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n"
    warnings = DataWarnings()
    assert list(parse_tum(text, "gt", warnings=warnings).t) == [1.0, 2.0]
    assert "repeated timestamp" in " ".join(warnings.lines())
    assert list(parse_tum(text, "trajectory.tum", ordered=False).t) == [1.0, 1.0, 2.0]


def test_too_few_poses_say_how_many_are_needed(tmp_path):
    with pytest.raises(DataError, match="holds no pose"):
        parse_tum(b"# only a comment\n", "est.txt")
    with pytest.raises(DataError, match="holds 1 row.* at least 2 are needed to interpolate"):
        parse_tum(b"1 0 0 0 0 0 0 1\n", "gt.txt", min_poses=2)
    with pytest.raises(DataError, match="cannot read the ground truth"):
        read_tum(tmp_path / "absent.txt", what="ground truth")


def test_a_quaternion_near_unit_is_kept_as_written_and_one_further_off_normalised():
    near = parse_tum(b"1 0 0 0 0 0 0 1.000000001\n", "x")
    assert near.q_w_c[0, 3] == 1.000000001
    off = parse_tum(b"1 0 0 0 0 0 0 1.001\n", "x")
    assert off.q_w_c[0, 3] == 1.0
