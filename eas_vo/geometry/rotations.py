"""Rotation helpers: the one SO(3) exponential and logarithm (rotvec_to_matrix, matrix_to_rotvec;
its compiled twin for numba kernels is geometry.compiled.exp_so3), quaternions (x, y, z, w everywhere,
converted here only), geodesic angles, slerp and the gyro's integrated rotation."""

from __future__ import annotations

from functools import reduce

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from eas_vo.types import ImuSeries, PoseSeries


def matrices_from_quats(q_xyzw: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w) -> (N, 3, 3) rotation matrices."""
    return Rotation.from_quat(np.asarray(q_xyzw, dtype=float)).as_matrix()


def quats_from_matrices(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices -> (N, 4) unit quaternions (x, y, z, w)."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()


def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Axis-angle vectors [rad] (..., 3) -> rotation matrices (..., 3, 3)."""
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix()


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> axis-angle vectors [rad] (..., 3)."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_rotvec()


def scaled_rotation(R: np.ndarray, factor: float) -> np.ndarray:
    """The rotation about the same axis as R (3, 3) by `factor` times its angle: Exp(factor Log(R))."""
    return rotvec_to_matrix(matrix_to_rotvec(R) * factor)


def gyro_rotation(imu: ImuSeries, t0: float, t1: float) -> np.ndarray | None:
    """R_0_1, the rotation of the IMU's frame from t0 to t1 >= t0 [s, its clock] by its gyro
    (rates linear between readings: ImuSeries.rates_between); None when the IMU does not
    measure [t0, t1] (ImuSeries.covered)."""
    if not imu.covered(t0, t1):
        return None
    rates, dt = imu.rates_between(t0, t1)
    return reduce(np.matmul, rotvec_to_matrix(rates * dt[:, None]), np.eye(3))


def geodesic_angle(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Angle [rad] of `R_a^T R_b`, i.e. ||log(R_a^-1 R_b)^v||; works on stacks (N, 3, 3)."""
    R_rel = np.swapaxes(np.asarray(R_a), -1, -2) @ np.asarray(R_b)
    cos = (np.trace(R_rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    # arccos is ill-conditioned near 0; use atan2 of sin and cos for precision.
    skew = np.stack(
        [
            R_rel[..., 2, 1] - R_rel[..., 1, 2],
            R_rel[..., 0, 2] - R_rel[..., 2, 0],
            R_rel[..., 1, 0] - R_rel[..., 0, 1],
        ],
        axis=-1,
    )
    sin = 0.5 * np.linalg.norm(skew, axis=-1)
    return np.arctan2(sin, cos)


def interpolate_poses(gt: PoseSeries, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground truth at times `t` [s]: slerp for rotation, linear for position.

    Returns:
        valid: (M,) bool, True where `t` lies within the ground truth's time span.
        R_w_c: (valid.sum(), 3, 3) interpolated rotations.
        p_w_c: (valid.sum(), 3) interpolated positions [m].
    """
    t = np.asarray(t, dtype=float)
    valid = (t >= gt.t[0]) & (t <= gt.t[-1])
    tv = t[valid]
    slerp = Slerp(gt.t, Rotation.from_quat(gt.q_w_c))
    R = slerp(tv).as_matrix() if len(tv) else np.empty((0, 3, 3))
    p = np.stack([np.interp(tv, gt.t, gt.p_w_c[:, k]) for k in range(3)], axis=-1)
    return valid, R, p


def euler_zyx_deg(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations -> (N, 3) roll, pitch, yaw [deg] (intrinsic z-y-x convention)."""
    yaw_pitch_roll = Rotation.from_matrix(R).as_euler("ZYX", degrees=True)
    return yaw_pitch_roll[:, ::-1]
