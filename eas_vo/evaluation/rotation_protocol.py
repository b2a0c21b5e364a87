"""The event-rotation benchmark's protocol, as CMax-SLAM scores it (Guo and Gallego, "CMax-SLAM:
Event-based Rotational-Motion Bundle Adjustment and SLAM System using Contrast Maximization",
IEEE T-RO 2024, arXiv 2403.08119, Table III): the first 30 s of a sequence, the motion-capture
ground truth low-pass filtered by a Gaussian on the rotation manifold, the estimate aligned to
it by the one pose at 1 s, the absolute error as the RMS rotation angle [deg] and the relative
error over 1 s spans on a 0.1 s grid [deg/s].

Every time here is on the ground truth's clock [s] (an estimate's time offset already applied);
`start_s` is the sequence's start on that clock, so no figure depends on the clock's origin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.evaluation.ape import scorable
from eas_vo.geometry.rotations import (
    geodesic_angle,
    interpolate_poses,
    matrices_from_quats,
    matrix_to_rotvec,
    quats_from_matrices,
    rotvec_to_matrix,
)
from eas_vo.types import PoseSeries

#: The protocol's name, as --protocol takes it.
NAME = "cmax-slam"

#: The scored window: the first 30 s of each sequence [s].
DURATION_S = 30.0

#: The estimate is aligned to the ground truth by the one pose this long after the start [s].
ALIGN_AT_S = 1.0

#: The ground truth's low-pass filter: "a Gaussian low-pass filter in the Lie group sense using a
#: time span of 50 ms" (Sec. IV-A), read as the window, as MATLAB's gausswin makes it: 11 taps of
#: the 200 Hz motion capture, sigma = (taps - 1) / (2 * 2.5), i.e. 10 ms, cut at 2.5 sigmas
#: either side (docs/rotation_benchmark.md: why this reading and not a 50 ms sigma).
SMOOTHING_SPAN_S = 0.05
SMOOTHING_TRUNCATE = 2.5
SMOOTHING_SIGMA_S = SMOOTHING_SPAN_S / (2 * SMOOTHING_TRUNCATE)

#: Times closer than this [s] are one time (a microsecond: the finest clock of an event camera;
#: a time difference rounds by 0.2 us on a Unix clock).
CLOCK_TOLERANCE_S = 1e-6

#: The relative error's span [s] and the grid its spans start on [s].
RELATIVE_SPAN_S = 1.0
RELATIVE_STEP_S = 0.1


def smooth_rotations(
    t: np.ndarray, R: np.ndarray, sigma_s: float = SMOOTHING_SIGMA_S, truncate: float = SMOOTHING_TRUNCATE
) -> np.ndarray:
    """A Gaussian low-pass of a rotation trajectory on the manifold: each R_k (times `t` [s],
    (N,), increasing; R (N, 3, 3)) replaced by R_k Exp(sum_j w_kj Log(R_k^T R_j)), the weighted
    mean of its neighbours within `truncate` sigmas in its own tangent space, w_kj proportional
    to exp(-(t_j - t_k)^2 / (2 sigma^2)) and normalised over the neighbours that exist (at the
    ends, the window is one-sided). Local, so it never wraps: rotation vectors about one
    reference would break on any turn beyond 180 degrees. `sigma_s` 0 returns R unchanged."""
    t, R = np.asarray(t, float), np.asarray(R, float)
    if sigma_s <= 0 or len(t) < 2:
        return R.copy()
    reach = truncate * sigma_s + CLOCK_TOLERANCE_S  # so that a symmetric window stays symmetric
    lo = np.searchsorted(t, t - reach, side="left")
    hi = np.searchsorted(t, t + reach, side="right")
    widest = int(np.max(np.maximum(np.arange(len(t)) - lo, hi - 1 - np.arange(len(t)))))
    tangent, total = np.zeros((len(t), 3)), np.zeros(len(t))
    k = np.arange(len(t))
    for offset in range(-widest, widest + 1):  # one neighbour per pose at a time: (N,) arrays, not (N, window)
        j = k + offset
        inside = (j >= lo) & (j < hi)
        kk, jj = k[inside], j[inside]
        w = np.exp(-0.5 * ((t[jj] - t[kk]) / sigma_s) ** 2)
        if offset:
            tangent[kk] += w[:, None] * matrix_to_rotvec(np.swapaxes(R[kk], 1, 2) @ R[jj])
        total[kk] += w
    return R @ rotvec_to_matrix(tangent / total[:, None])


@dataclass(frozen=True)
class ProtocolScore:
    """An estimate scored by the protocol.

    Attributes:
        t: (N,) the estimate's pose times scored [s from the sequence's start].
        error_deg: (N,) each one's rotation angle against the smoothed ground truth [deg].
        relative_t: (M,) start times of the relative spans scored [s from the start].
        relative_deg_s: (M,) each span's error: the angle between the two relative rotations
            over it, divided by its length [deg/s].
        align_at_s: where the estimate was aligned [s from the start].
    """

    t: np.ndarray
    error_deg: np.ndarray
    relative_t: np.ndarray
    relative_deg_s: np.ndarray
    align_at_s: float

    def summary(self) -> dict:
        """absolute_rms_deg (the protocol's absolute error), relative_rms_deg_s (its relative
        error), their means and maxima, and how many poses and spans they cover; None where
        nothing was scored."""

        def stats(x: np.ndarray, name: str, unit: str) -> dict:
            return {
                f"{name}_rms_{unit}": float(np.sqrt(np.mean(x**2))) if len(x) else None,
                f"{name}_mean_{unit}": float(np.mean(x)) if len(x) else None,
                f"{name}_max_{unit}": float(np.max(x)) if len(x) else None,
            }

        return {
            **stats(self.error_deg, "absolute", "deg"),
            **stats(self.relative_deg_s, "relative", "deg_s"),
            "poses_scored": len(self.t),
            "spans_scored": len(self.relative_t),
        }


def score(
    estimate: PoseSeries,
    ground_truth: PoseSeries,
    start_s: float,
    duration_s: float = DURATION_S,
    align_at_s: float = ALIGN_AT_S,
    sigma_s: float = SMOOTHING_SIGMA_S,
) -> ProtocolScore:
    """The protocol on `estimate` against `ground_truth` (both on the ground truth's clock [s]),
    over [start_s, start_s + duration_s]: the ground truth smoothed (smooth_rotations, `sigma_s`),
    both slerped at start_s + align_at_s and the estimate rotated by the one R_gt R_est^T that
    makes them equal there; the absolute error at each of the estimate's poses in the window
    that the ground truth scores (ape.scorable: no wide gap interpolated), the relative error
    on spans [s, s + RELATIVE_SPAN_S] with s on a RELATIVE_STEP_S grid from start_s, where both
    trajectories cover the span. Raises ValueError when the alignment time is not covered by both."""
    R_gt = smooth_rotations(ground_truth.t, matrices_from_quats(ground_truth.q_w_c), sigma_s)
    smoothed = PoseSeries(ground_truth.t, ground_truth.p_w_c, quats_from_matrices(R_gt))
    t_align = start_s + align_at_s
    for name, series in (("estimate", estimate), ("ground truth", ground_truth)):
        if not scorable(series.t, np.array([t_align]))[0]:
            raise ValueError(
                f"the {name} does not cover the alignment time, {align_at_s:g} s after the start "
                f"(it spans {series.t[0] - start_s:.3f} to {series.t[-1] - start_s:.3f} s)"
            )
    R_gt_align = interpolate_poses(smoothed, np.array([t_align]))[1][0]
    R_est_align = interpolate_poses(estimate, np.array([t_align]))[1][0]
    align = R_gt_align @ R_est_align.T

    end = start_s + duration_s
    poses = np.flatnonzero((estimate.t >= start_s) & (estimate.t <= end))
    poses = poses[scorable(ground_truth.t, estimate.t[poses])]
    t, R_est = estimate.t[poses], align @ matrices_from_quats(estimate.q_w_c[poses])
    error = np.degrees(geodesic_angle(interpolate_poses(smoothed, t)[1], R_est)) if len(t) else np.empty(0)

    s = start_s + RELATIVE_STEP_S * np.arange(
        int(np.floor((duration_s - RELATIVE_SPAN_S) / RELATIVE_STEP_S + 1e-9)) + 1
    )
    e = s + RELATIVE_SPAN_S
    both = np.concatenate([s, e])
    covered = scorable(ground_truth.t, both) & scorable(estimate.t, both)
    keep = covered[: len(s)] & covered[len(s) :]
    s, e = s[keep], e[keep]
    relative = np.empty(0)
    if len(s):
        G0, G1 = interpolate_poses(smoothed, s)[1], interpolate_poses(smoothed, e)[1]
        E0, E1 = interpolate_poses(estimate, s)[1], interpolate_poses(estimate, e)[1]
        relative = np.degrees(geodesic_angle(np.swapaxes(G0, 1, 2) @ G1, np.swapaxes(E0, 1, 2) @ E1)) / RELATIVE_SPAN_S
    return ProtocolScore(t - start_s, error, s - start_s, relative, align_at_s)
