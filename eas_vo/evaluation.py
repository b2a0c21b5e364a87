"""Accuracy against ground truth: the paper's average APE (Eq. 3) and correspondence counts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.geometry import geodesic_angle, interpolate_poses
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
    R_est = np.asarray(R_w_c)[valid]
    if len(R_est) == 0:
        empty = np.empty((0, 3, 3))
        return RotationErrors(valid, empty, np.empty((0, 3)), empty, np.empty(0))
    R_aligned = R_gt[0] @ R_est[0].T @ R_est
    return RotationErrors(valid, R_gt, p_gt, R_aligned, geodesic_angle(R_gt, R_aligned))
