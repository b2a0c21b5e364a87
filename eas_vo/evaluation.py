"""Accuracy against ground truth: the paper's average APE (Eq. 3) and correspondence counts."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, interpolate_poses, matrices_from_quats
from eas_vo.types import PoseSeries


@dataclass(frozen=True)
class RotationErrors:
    """Per-frame rotation error of an estimate against ground truth.

    Attributes:
        valid: (N,) frames with ground truth (frame time + offset inside its span).
        R_w_c_gt: (valid.sum(), 3, 3) ground truth at the valid frames.
        p_w_c_gt: (valid.sum(), 3) ground-truth positions [m] at the valid frames.
        R_w_c_aligned: (valid.sum(), 3, 3) the estimate aligned to ground truth at the first valid frame.
        ape_rad: (valid.sum(),) ||log(R_gt^-1 R_est)^v|| per valid frame [rad].
    """

    valid: np.ndarray
    R_w_c_gt: np.ndarray
    p_w_c_gt: np.ndarray
    R_w_c_aligned: np.ndarray
    ape_rad: np.ndarray

    def summary(self) -> dict:
        """Mean (the paper's average APE), RMSE, median and max [rad]; NaN without ground truth."""
        e = self.ape_rad
        if len(e) == 0:
            return {k: float("nan") for k in ("ape_mean_rad", "ape_rmse_rad", "ape_median_rad", "ape_max_rad")}
        return {
            "ape_mean_rad": float(e.mean()),
            "ape_rmse_rad": float(np.sqrt(np.mean(e**2))),
            "ape_median_rad": float(np.median(e)),
            "ape_max_rad": float(e.max()),
        }


def rotation_errors(
    t: np.ndarray, R_w_c: np.ndarray, ground_truth: PoseSeries, time_offset_s: float = 0.0
) -> RotationErrors:
    """Eq. 3 per frame: ground truth slerped at `t + time_offset_s`, estimate aligned at the first frame.

    The alignment is evo's `--align_origin`: R_aligned_k = R_gt_0 R_est_0^T R_est_k.
    """
    valid, R_gt, p_gt = interpolate_poses(ground_truth, np.asarray(t) + time_offset_s)
    R_aligned, ape = aligned_errors(R_gt, np.asarray(R_w_c)[valid])
    return RotationErrors(valid, R_gt, p_gt if len(ape) else np.empty((0, 3)), R_aligned, ape)


def aligned_errors(R_w_c_gt: np.ndarray, R_w_c_est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The estimate aligned at the first frame (evo's `--align_origin`), and Eq. 3's error per
    frame [rad]: R_aligned_k = R_gt_0 R_est_0^T R_est_k, ape_k = ||log(R_gt_k^-1 R_aligned_k)||.

    Both stacks (N, 3, 3) hold the same frames in the same order."""
    if len(R_w_c_est) == 0:
        return np.empty((0, 3, 3)), np.empty(0)
    R_aligned = R_w_c_gt[0] @ R_w_c_est[0].T @ R_w_c_est
    return R_aligned, geodesic_angle(R_w_c_gt, R_aligned)


def tum_rotation_errors(estimate_tum: Path, groundtruth_tum: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(t - t0 [s], error per frame [rad]) of two TUM files over their common timestamps,
    aligned at the first (as `rotation_errors`); None if either is unreadable or they share none."""
    from eas_vo.io import read_tum

    try:
        t_est, _, q_est = read_tum(estimate_tum)
        t_gt, _, q_gt = read_tum(groundtruth_tum)
    except (OSError, ValueError):
        return None
    common, i_est, i_gt = np.intersect1d(t_est, t_gt, return_indices=True)
    if len(common) == 0:
        return None
    _, ape = aligned_errors(matrices_from_quats(q_gt[i_gt]), matrices_from_quats(q_est[i_est]))
    return common - common[0], ape


def estimate_time_offset(t: np.ndarray, edges, ground_truth: PoseSeries, search_s: float = 0.1) -> float:
    """The offset [s] to add to frame times so that ground truth best explains the measured rotations.

    For a candidate offset d, each measured relative rotation R_i_j is compared with the
    ground truth's between t_i + d and t_j + d; the cost is the mean geodesic error of the
    best 80 % (robust to tracking failures). A 2 ms grid over [-search_s, search_s] is
    refined to 0.1 ms around its best point. Needs a moving camera; 0 with too few edges.
    """
    from scipy.spatial.transform import Rotation, Slerp

    t = np.asarray(t, dtype=float)
    edges = [e for e in edges if 0 <= e.i < len(t) and 0 <= e.j < len(t)]
    if len(edges) < 5:
        return 0.0
    i = np.array([e.i for e in edges])
    j = np.array([e.j for e in edges])
    R_meas = np.stack([e.R_i_j for e in edges])
    slerp = Slerp(ground_truth.t, Rotation.from_quat(ground_truth.q_w_c))
    span = (ground_truth.t[0], ground_truth.t[-1])

    def cost(offset: float) -> float:
        tt = t + offset
        use = (tt[i] >= span[0]) & (tt[j] <= span[1])
        if use.sum() < max(5, len(edges) // 2):
            return np.inf
        R_i = slerp(tt[i[use]]).as_matrix()
        R_j = slerp(tt[j[use]]).as_matrix()
        errors = np.sort(geodesic_angle(np.swapaxes(R_i, 1, 2) @ R_j, R_meas[use]))
        return float(errors[: max(1, int(0.8 * len(errors)))].mean())

    coarse = np.arange(-search_s, search_s + 1e-9, 0.002)
    best = coarse[np.argmin([cost(d) for d in coarse])]
    fine = best + np.arange(-0.002, 0.002 + 1e-9, 0.0001)
    return float(fine[np.argmin([cost(d) for d in fine])])
