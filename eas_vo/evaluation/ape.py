"""The paper's average APE of rotation (Eq. 3): each frame's estimate against the ground truth
interpolated at its time, after aligning the first frames; only frames the ground truth scores
(no wide gap interpolated)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, interpolate_poses, matrices_from_quats
from eas_vo.types import MAX_GAP_READINGS, PoseSeries

#: Below this fraction of a run's frames scored, its summary warns: the APE then describes a
#: part of the run only (a tenth of the frames unscored is about a lost ground-truth sample at
#: each end of a short run, or a marker occluded for a moment).
MIN_SCORED_FRACTION = 0.9


#: Ground truth is never interpolated across more than this many of the run's median frame
#: intervals (half a second at a DAVIS's 20 Hz): slerp turns at a constant rate between two
#: poses, and hand-held motion reverses within about a second.
MAX_GAP_FRAMES = 10


def ground_truth_gap_limit_s(gt_t: np.ndarray, t: np.ndarray) -> float:
    """The widest gap [s] between two ground-truth poses (times `gt_t` [s]) a frame between them
    is scored across, for frames at times `t` [s]: MAX_GAP_READINGS (a sample or three lost, as
    for the IMU) of the ground truth's median sample interval, and at most MAX_GAP_FRAMES of the
    frames' (two poses 1.1 s apart have a median interval of 1.1 s: only the frames' bound tells
    that they guess the motion of the 20 frames between them)."""
    limits = []
    for x, factor in ((gt_t, MAX_GAP_READINGS), (t, MAX_GAP_FRAMES)):
        d = np.diff(np.asarray(x, float))
        if np.any(d > 0):
            limits.append(factor * float(np.median(d[d > 0])))
    return min(limits, default=np.inf)


def scorable(gt_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Which times `t` [s] (ground truth's clock) ground truth at `gt_t` [s] scores: within its
    span and between two poses at most ground_truth_gap_limit_s apart (a pose at the time itself
    scores it)."""
    gt_t, t = np.asarray(gt_t, float), np.asarray(t, float)
    if len(gt_t) == 0:
        return np.zeros(len(t), bool)
    after = np.clip(np.searchsorted(gt_t, t, side="left"), 1, max(len(gt_t) - 1, 1))
    exact = gt_t[np.clip(np.searchsorted(gt_t, t), 0, len(gt_t) - 1)] == t
    gap = gt_t[after] - gt_t[after - 1] if len(gt_t) > 1 else np.full(len(t), np.inf)
    return (t >= gt_t[0]) & (t <= gt_t[-1]) & (exact | (gap <= ground_truth_gap_limit_s(gt_t, t)))


@dataclass(frozen=True)
class RotationErrors:
    """Per-frame rotation error of an estimate against ground truth.

    Attributes:
        valid: (N,) frames the ground truth scores (frame time + offset inside its span and
            not in a gap wider than `max_gap_s`: scorable).
        R_w_c_gt: (valid.sum(), 3, 3) ground truth at the valid frames.
        p_w_c_gt: (valid.sum(), 3) ground-truth positions [m] at the valid frames.
        R_w_c_aligned: (valid.sum(), 3, 3) the estimate aligned to ground truth at the first valid frame.
        ape_rad: (valid.sum(),) ||log(R_gt^-1 R_est)^v|| per valid frame [rad].
        ground_truth_span_s: the ground truth's first and last time on the frames' clock [s].
        max_gap_s: the widest gap between poses a frame is scored across [s] (ground_truth_gap_limit_s).
    """

    valid: np.ndarray
    R_w_c_gt: np.ndarray
    p_w_c_gt: np.ndarray
    R_w_c_aligned: np.ndarray
    ape_rad: np.ndarray
    ground_truth_span_s: tuple[float, float] = (np.nan, np.nan)
    max_gap_s: float = np.inf

    def coverage(self, t: np.ndarray) -> dict:
        """What the ground truth scores of a run at frame times `t` [s] (metrics.json):
        frames_scored_fraction (frames_evaluated / frames), ground_truth_span_s (its first and
        last time [s] from the run's first frame, on the frames' clock),
        ground_truth_max_gap_s (the widest gap scored across) and frames_in_ground_truth_gaps
        (frames within its span left unscored)."""
        t = np.asarray(t, float)
        inside = (t >= self.ground_truth_span_s[0]) & (t <= self.ground_truth_span_s[1])
        return {
            "frames_scored_fraction": float(self.valid.mean()) if len(t) else 0.0,
            "ground_truth_span_s": [
                self.ground_truth_span_s[0] - float(t[0]),
                self.ground_truth_span_s[1] - float(t[0]),
            ],
            "ground_truth_max_gap_s": float(self.max_gap_s),
            "frames_in_ground_truth_gaps": int(np.sum(inside & ~self.valid)),
        }

    def coverage_warning(self, t: np.ndarray) -> list[str]:
        """One line when the ground truth scores fewer than MIN_SCORED_FRACTION of the frames at
        `t` [s]: how many, over what span against the run's, and the frames left in its gaps."""
        n, scored = len(self.valid), int(self.valid.sum())
        if n == 0 or scored >= MIN_SCORED_FRACTION * n:
            return []
        c = self.coverage(t)
        gaps = c["frames_in_ground_truth_gaps"]
        in_gaps = (
            f"; {gaps} frames lie in its gaps wider than {c['ground_truth_max_gap_s']:.3g} s, across which it is "
            "not interpolated"
            if gaps
            else ""
        )
        start, end = c["ground_truth_span_s"]
        said = (
            f"the ground truth scores only {scored} of the run's {n} frames ({100 * scored / n:.0f} %, under "
            f"{100 * MIN_SCORED_FRACTION:.0f} %): it spans {start:.3f} to {end:.3f} s of the run's 0 to {t[-1] - t[0]:.3f} s"
            f"{in_gaps}; the APE describes those frames only"
        )
        return [said]

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
    """Eq. 3 per frame: ground truth slerped at `t + time_offset_s` where it can score them
    (scorable: no wider gap than ground_truth_gap_limit_s), estimate aligned at the first frame
    that has ground truth.

    The alignment is evo's `--align_origin`: R_aligned_k = R_gt_0 R_est_0^T R_est_k.
    """
    at = np.asarray(t, float) + time_offset_s
    valid = scorable(ground_truth.t, at)
    _, R_gt, p_gt = interpolate_poses(ground_truth, at[valid])
    R_aligned, ape = aligned_errors(R_gt, np.asarray(R_w_c)[valid])
    span = (float(ground_truth.t[0]) - time_offset_s, float(ground_truth.t[-1]) - time_offset_s)
    return RotationErrors(
        valid,
        R_gt,
        p_gt if len(ape) else np.empty((0, 3)),
        R_aligned,
        ape,
        span,
        ground_truth_gap_limit_s(ground_truth.t, at),
    )


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
    aligned = tum_aligned_rotations(estimate_tum, groundtruth_tum)
    if aligned is None:
        return None
    t, R_gt, R_aligned = aligned
    return t - t[0], geodesic_angle(R_gt, R_aligned)


def tum_aligned_rotations(
    estimate_tum: Path, groundtruth_tum: Path
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(common timestamps [s], R_w_c ground truth, R_w_c estimate aligned at the first) of two
    TUM files; None if either is unreadable or they share no timestamp."""
    from eas_vo.errors import EasVoError
    from eas_vo.io.tum import read_tum

    try:
        estimate, gt = read_tum(estimate_tum, ordered=False), read_tum(groundtruth_tum, ordered=False)
    except EasVoError:
        return None
    t_est, q_est, t_gt, q_gt = estimate.t, estimate.q_w_c, gt.t, gt.q_w_c
    common, i_est, i_gt = np.intersect1d(t_est, t_gt, return_indices=True)
    if len(common) == 0:
        return None
    R_gt = matrices_from_quats(q_gt[i_gt])
    R_aligned, _ = aligned_errors(R_gt, matrices_from_quats(q_est[i_est]))
    return common, R_gt, R_aligned
