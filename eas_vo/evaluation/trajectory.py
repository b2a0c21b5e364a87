"""The trajectory APE of a 6-DoF estimate (ORB-SLAM's), as evo_ape computes it: association by
time, Umeyama alignment (Sim(3), SE(3)) or the first pose, translation and rotation errors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, matrices_from_quats
from eas_vo.types import PoseSeries

ALIGNMENTS = ("sim3", "se3", "origin")


#: The cross-covariance's singular values of two point sets whose second is below this
#: fraction of the first: the sets are collinear to within rounding (umeyama).
COLLINEAR = 1e-9


#: The largest standard uncertainty [rad] of a sim3 / se3 alignment's rotation (about 3
#: degrees) that still measures a rotation APE (alignment_uncertainty).
ALIGN_UNCERTAINTY_RAD = 0.05


#: What a sim3 / se3 alignment that the estimate's positions cannot fix says to do instead:
#: the origin alignment takes only the first pose, so it scores a rotation-only trajectory
#: (eas-vo's own, positions 0).
ORIGIN_INSTEAD = (
    "; to score the rotations alone (e.g. a rotation-only trajectory), align at the first pose: --align origin"
)


@dataclass(frozen=True)
class TrajectoryApe:
    """An estimated 6-DoF trajectory against ground truth, after alignment (as evo_ape).

    Attributes:
        t: (M,) timestamps [s] of the matched estimate poses.
        R_align, t_align, scale: the alignment applied to the estimate, p' = scale R_align p + t_align,
            R' = R_align R (camera-to-world).
        trans_error_m: (M,) |p_gt - p'| [m].
        rot_error_rad: (M,) ||log(R_gt^-1 R')|| [rad] (Eq. 3).
    """

    t: np.ndarray
    R_align: np.ndarray
    t_align: np.ndarray
    scale: float
    trans_error_m: np.ndarray
    rot_error_rad: np.ndarray

    def aligned(self, p_w_c: np.ndarray, R_w_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Estimate poses (N, 3) [m], (N, 3, 3) mapped by the alignment into the ground truth's world."""
        return similarity_transform(self.R_align, self.t_align, self.scale, p_w_c, R_w_c)

    def summary(self) -> dict:
        e, r = self.trans_error_m, self.rot_error_rad
        return {
            "ape_trans_mean_m": float(e.mean()),
            "ape_trans_rmse_m": float(np.sqrt(np.mean(e**2))),
            "ape_trans_max_m": float(e.max()),
            "ape_rot_mean_rad": float(r.mean()),
            "ape_rot_rmse_rad": float(np.sqrt(np.mean(r**2))),
            "scale": float(self.scale),
            "matched_poses": int(len(e)),
        }


def associate(t_ref: np.ndarray, t_est: np.ndarray, max_diff_s: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i_ref, i_est) of nearest timestamps within `max_diff_s`, as evo's
    `associate_trajectories`: each time of the series with fewer poses (the estimate on a
    tie) takes the nearest of the other (the earlier one on a tie); both sorted."""
    short, long_ = (t_ref, t_est) if len(t_ref) < len(t_est) else (t_est, t_ref)
    upper = np.clip(np.searchsorted(long_, short, side="right"), 0, len(long_) - 1)
    d_upper = long_[upper] - short
    d_lower = np.where(upper > 0, short - long_[np.maximum(upper - 1, 0)], np.inf)
    take_upper = (d_upper <= max_diff_s) & (d_upper < d_lower)
    take_lower = ~take_upper & (d_lower <= max_diff_s) & (d_lower <= d_upper)
    keep = (take_upper | take_lower) & (short >= long_[0] - max_diff_s) & (short <= long_[-1] + max_diff_s)
    i_short = np.flatnonzero(keep)
    i_long = np.where(take_upper, upper, upper - 1)[keep]
    return (i_short, i_long) if len(t_ref) < len(t_est) else (i_long, i_short)


def umeyama(x: np.ndarray, y: np.ndarray, with_scale: bool) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(R, t, s) minimising sum |y_k - (s R x_k + t)|^2 over points x, y (N, 3)
    (Umeyama, IEEE PAMI 1991, eqs. 34-43); s = 1 without scale. Solved on the centred points
    divided by their largest coordinate (no overflow for any finite input). None if degenerate:
    the points' cross-covariance has a second singular value below COLLINEAR of its first
    (either set collinear, or a point, to within rounding)."""
    mean_x, mean_y = x.mean(axis=0), y.mean(axis=0)
    size_x, size_y = np.abs(x - mean_x).max(), np.abs(y - mean_y).max()
    if not (size_x > 0 and size_y > 0):
        return None
    dx, dy = (x - mean_x) / size_x, (y - mean_y) / size_y
    U, d, Vt = np.linalg.svd(dy.T @ dx / len(x))
    if d[1] <= COLLINEAR * d[0]:
        return None
    S = np.diag([1.0, 1.0, -1.0 if np.linalg.det(U) * np.linalg.det(Vt) < 0 else 1.0])
    R = U @ S @ Vt
    var_x = float(np.mean(np.sum(dx**2, axis=1)))
    s = float(np.trace(np.diag(d) @ S) / var_x) * (size_y / size_x) if with_scale else 1.0
    return R, mean_y - s * R @ mean_x, s


def similarity_transform(R_a: np.ndarray, t_a: np.ndarray, s: float, p_w_c: np.ndarray, R_w_c: np.ndarray):
    """Poses (N, 3) [m], (N, 3, 3) under x -> s R_a x + t_a: (s p R_a^T + t_a, R_a R)."""
    return s * p_w_c @ R_a.T + t_a, R_a @ R_w_c


def trajectory_ape(ground_truth: PoseSeries, estimate: PoseSeries, align: str = "sim3", max_diff_s: float = 0.01):
    """Translation and rotation APE of `estimate` (camera-to-world poses) after `align`:
    sim3 (Umeyama with scale: evo_ape -as, for monocular SLAM), se3 (-a) or origin (first
    poses made equal: --align_origin).

    What each alignment needs, else ValueError (for sim3 and se3 naming origin instead: a
    rotation-only trajectory has no positions to align): origin, 2 matched poses (the first
    one's error is 0 by construction); sim3 and se3, 3 matched poses whose positions span a
    plane in both trajectories (umeyama) and fix the alignment's rotation to within
    ALIGN_UNCERTAINTY_RAD (alignment_uncertainty, with the position noise the best similarity
    leaves: a wrong scale under se3 is an error to measure, not noise); and every figure finite.
    """
    i_gt, i_est = associate(ground_truth.t, estimate.t, max_diff_s)
    least = 2 if align == "origin" else 3
    if len(i_gt) < least:
        instead = ORIGIN_INSTEAD if len(i_gt) >= 2 else ""
        raise ValueError(
            f"{len(i_gt)} estimate pose(s) within {max_diff_s} s of a ground-truth pose; "
            f"{align} alignment needs at least {least}{instead}"
        )
    p_gt, R_gt = ground_truth.p_w_c[i_gt], matrices_from_quats(ground_truth.q_w_c[i_gt])
    p_est, R_est = estimate.p_w_c[i_est], matrices_from_quats(estimate.q_w_c[i_est])
    if align == "origin":
        R_a = R_gt[0] @ R_est[0].T
        t_a, s = p_gt[0] - R_a @ p_est[0], 1.0
    else:
        similar = umeyama(p_est, p_gt, with_scale=True)
        if similar is None:
            raise ValueError(
                f"the positions of the {len(i_gt)} matched poses lie on a line or a point; "
                f"{align} alignment needs them to span a plane{ORIGIN_INSTEAD}"
            )
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below
            shape_error_m = np.linalg.norm(p_gt - similarity_transform(*similar, p_est, R_est)[0], axis=1)
        uncertainty = alignment_uncertainty(p_gt, shape_error_m, dof=7)
        if uncertainty > ALIGN_UNCERTAINTY_RAD:
            raise ValueError(
                f"the {len(i_gt)} matched positions fix the {align} alignment's rotation only to about "
                f"{uncertainty:.2g} rad ({ALIGN_UNCERTAINTY_RAD:g} at most): they spread too little across "
                f"their main direction for how far they miss the ground truth{ORIGIN_INSTEAD}"
            )
        R_a, t_a, s = similar if align == "sim3" else umeyama(p_est, p_gt, with_scale=False)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below
        p_aligned, R_aligned = similarity_transform(R_a, t_a, s, p_est, R_est)
        ape = TrajectoryApe(
            estimate.t[i_est], R_a, t_a, s, np.linalg.norm(p_gt - p_aligned, axis=1), geodesic_angle(R_gt, R_aligned)
        )
        finite = np.isfinite(list(ape.summary().values())).all()
    if not (finite and s > 0):
        raise ValueError(
            f"positions up to {np.abs(p_est).max():.3g} m: the errors after {align} alignment overflow floating point"
        )
    return ape


def alignment_uncertainty(p_gt: np.ndarray, error_m: np.ndarray, dof: int) -> float:
    """The standard uncertainty [rad] of an alignment's rotation about the ground-truth
    positions' main direction, the least constrained axis: sigma / sqrt(sum rho_k^2), with
    sigma^2 [m^2] the position noise per coordinate the residuals `error_m` (N,) [m] show
    (their squares summed over 3N - dof) and rho_k [m] each position's distance from the main
    axis through their mean (p_gt (N, 3) [m]). inf without residual degrees of freedom."""
    centred = p_gt - p_gt.mean(axis=0)
    main = np.linalg.svd(centred, full_matrices=False)[2][0]
    across = float(np.sum(centred**2) - np.sum((centred @ main) ** 2))
    free = 3 * len(p_gt) - dof
    if free <= 0 or across <= 0:
        return np.inf
    return float(np.sqrt(np.sum(error_m**2) / free / across))
