"""TUM trajectories (`t tx ty tz qx qy qz qw` a line, camera-to-world; `#` comments): the one
reader and writer, for ground truth, eas-vo's own trajectories and other tools' estimates.

Every file is held to the same rules, each error naming the file and its line: times
increase (a repeated time is dropped and counted with `warnings`, --lenient), quaternions
are unit to within 1e-2 (a quaternion further off than UNIT_NORM_TOLERANCE is normalised)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eas_vo.errors import DataError, DataWarnings
from eas_vo.geometry.rotations import quats_from_matrices
from eas_vo.io.tables import check_increasing, clock_time, data_line, parse_table, row_number
from eas_vo.types import PoseSeries

#: What one row holds, for messages.
TUM_ROW = "t px py pz qx qy qz qw"

#: A quaternion this close to unit norm is kept as read: one written with 9 decimals (the ECD's
#: and eas-vo's groundtruth.txt) is up to 1e-9 off unit, and normalising it would change its
#: 9th decimal, so that a written sequence would not read back as it was.
UNIT_NORM_TOLERANCE = 1e-8


def pose_series(where: str, table: np.ndarray, line_of=row_number) -> PoseSeries:
    """`t tx ty tz qx qy qz qw` rows -> PoseSeries, checking that quaternions are unit
    (`line_of(row)`: what a message names, as for tables.check_increasing)."""
    q = table[:, 4:8]
    with np.errstate(over="ignore"):  # a component of 1e300: its norm is inf, refused below
        norms = np.linalg.norm(q, axis=1)
    off = ~(np.abs(norms - 1.0) <= 1e-2)
    if off.any():
        i = int(np.argmax(off))
        raise DataError(where, f"quaternion norm {norms[i]:.3f} is not 1", line_of(i))
    q = np.where(np.abs(norms - 1.0)[:, None] > UNIT_NORM_TOLERANCE, q / norms[:, None], q)
    return PoseSeries(t=table[:, 0], p_w_c=table[:, 1:4], q_w_c=q)


def parse_tum(
    data: bytes,
    where: str,
    time_offset_s: float = 0.0,
    origin_ns: int = 0,
    warnings: DataWarnings | None = None,
    min_poses: int = 1,
    ordered: bool = True,
) -> PoseSeries:
    """The poses of TUM text `data` (`where` names it in messages), `time_offset_s` [s] added to
    each time (the file's clock -> the recording's), read after the recording's clock origin
    `origin_ns` [ns] (Dataset.clock_origin_ns); at least `min_poses` of them (ground truth
    needs 2 to interpolate between). `ordered` False keeps every row as it is, for eas-vo's own
    trajectories: one row a frame, frames at the same time included."""
    table = parse_table(data, where, 8, TUM_ROW)
    if len(table) < min_poses:
        raise DataError(
            where,
            "holds no pose"
            if min_poses == 1
            else f"holds {len(table)} row(s) of '{TUM_ROW}'; at least "
            f"{min_poses} are needed to interpolate (or remove the file)",
        )
    keep = (
        check_increasing(where, table[:, 0], lambda row: data_line(data, row), warnings)
        if ordered
        else np.arange(len(table))
    )
    poses = pose_series(where, table[keep], lambda row: data_line(data, int(keep[row])))
    if time_offset_s == 0.0 and origin_ns == 0:
        return poses
    # offset and origin first: a ground truth from 0 beside a Unix-time recording loses no digits
    return PoseSeries(poses.t + (time_offset_s - origin_ns / 1e9), poses.p_w_c, poses.q_w_c)


def read_tum(
    path: str | Path,
    time_offset_s: float = 0.0,
    origin_ns: int = 0,
    warnings: DataWarnings | None = None,
    min_poses: int = 1,
    ordered: bool = True,
    what: str = "trajectory",
) -> PoseSeries:
    """The poses of the TUM file `path` (see parse_tum); `what` it holds, for the message when
    it cannot be read."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise DataError(str(path), f"cannot read the {what}: {exc.strerror or exc}") from None
    return parse_tum(data, str(path), time_offset_s, origin_ns, warnings, min_poses, ordered)


def format_tum(t: np.ndarray, p: np.ndarray, R: np.ndarray, origin_ns: int = 0) -> str:
    """TUM lines for times `t` [s] after the clock origin `origin_ns` [ns], positions `p` [m]
    (N, 3) and camera-to-world rotations `R` (N, 3, 3)."""
    q = quats_from_matrices(R) if len(R) else np.empty((0, 4))
    rows = np.column_stack([p, q])
    return "".join(
        f"{clock_time(ti, origin_ns)} {r[0]:.9f} {r[1]:.9f} {r[2]:.9f} {r[3]:.12f} {r[4]:.12f} {r[5]:.12f} {r[6]:.12f}\n"
        for ti, r in zip(t, rows)
    )
