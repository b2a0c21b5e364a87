"""Accuracy against ground truth: the paper's average APE of rotation (Eq. 3) for a run or a
TUM trajectory, the ground truth's time offset, the trajectory APE (ORB-SLAM runs), and how the
IMU's gyro agrees with the tracked rotations."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, interpolate_poses, matrices_from_quats, matrix_to_rotvec
from eas_vo.types import MAX_GAP_READINGS, ImuSeries, PoseSeries

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
        return {"frames_scored_fraction": float(self.valid.mean()) if len(t) else 0.0,
                "ground_truth_span_s": [self.ground_truth_span_s[0] - float(t[0]), self.ground_truth_span_s[1] - float(t[0])],
                "ground_truth_max_gap_s": float(self.max_gap_s),
                "frames_in_ground_truth_gaps": int(np.sum(inside & ~self.valid))}

    def coverage_warning(self, t: np.ndarray) -> list[str]:
        """One line when the ground truth scores fewer than MIN_SCORED_FRACTION of the frames at
        `t` [s]: how many, over what span against the run's, and the frames left in its gaps."""
        n, scored = len(self.valid), int(self.valid.sum())
        if n == 0 or scored >= MIN_SCORED_FRACTION * n:
            return []
        c = self.coverage(t)
        gaps = c["frames_in_ground_truth_gaps"]
        in_gaps = (f"; {gaps} frames lie in its gaps wider than {c['ground_truth_max_gap_s']:.3g} s, across which it is "
                   "not interpolated" if gaps else "")
        start, end = c["ground_truth_span_s"]
        said = (f"the ground truth scores only {scored} of the run's {n} frames ({100 * scored / n:.0f} %, under "
                f"{100 * MIN_SCORED_FRACTION:.0f} %): it spans {start:.3f} to {end:.3f} s of the run's 0 to {t[-1] - t[0]:.3f} s"
                f"{in_gaps}; the APE describes those frames only")
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


#: The interval of the relative pose error [s], as the event-rotation literature reports it.
RPE_DELTA_S = 1.0


def angular_velocities(t: np.ndarray, edges, errors: RotationErrors | None = None):
    """Each consecutive edge's mean angular velocity, log(R_i_j) / (t_j - t_i) [rad/s] (camera
    frame of frame i): (mid-interval times [s] (K,), estimates (K, 3), and the ground truth's
    over the same intervals (K, 3), or None without `errors`). With `errors`, only edges whose
    frames both have ground truth."""
    t = np.asarray(t)
    usable = [e for e in edges if e.j == e.i + 1 and not e.loop and 0 <= e.i and e.j < len(t) and t[e.j] > t[e.i]]
    at = {} if errors is None else {int(k): n for n, k in enumerate(np.flatnonzero(errors.valid))}
    if errors is not None:
        usable = [e for e in usable if e.i in at and e.j in at]
    if not usable:
        return np.empty(0), np.empty((0, 3)), None if errors is None else np.empty((0, 3))
    dt = np.array([t[e.j] - t[e.i] for e in usable])
    mid = np.array([0.5 * (t[e.i] + t[e.j]) for e in usable])
    est = matrix_to_rotvec(np.stack([e.R_i_j for e in usable])) / dt[:, None]
    if errors is None:
        return mid, est, None
    R = errors.R_w_c_gt
    gt = matrix_to_rotvec(np.stack([R[at[e.i]].T @ R[at[e.j]] for e in usable])) / dt[:, None]
    return mid, est, gt


def motion_errors(t: np.ndarray, errors: RotationErrors, edges, delta_s: float = RPE_DELTA_S) -> dict:
    """The errors the event-rotation literature reports, against the ground truth `errors` holds
    (sampled at the frame times plus the run's time offset):

    - angular velocity: each consecutive edge's rotation vector over its interval
      (log(R_i_j) / (t_j - t_i), camera frame of frame i, for frame trackers and cmax alike)
      against the ground truth's over the same interval; RMS per camera axis and of the error
      vector's norm [deg/s] (omega_rms_*), over `omega_pairs` edges;
    - RPE of rotation over `delta_s`: for every frame i, the frame j nearest t_i + delta_s
      (within half the median frame interval), the angle of (R_gt_i^T R_gt_j)^T (R_i^T R_j)
      [deg], mean and RMS (rpe_1s_*), over `rpe_pairs` pairs.
    Values are None where nothing could be compared."""
    frames = np.flatnonzero(errors.valid)
    R_gt, R_est = errors.R_w_c_gt, errors.R_w_c_aligned
    _, est, gt = angular_velocities(t, edges, errors)
    out: dict = {"omega_pairs": len(est)}
    names = ("omega_rms_x_deg_s", "omega_rms_y_deg_s", "omega_rms_z_deg_s", "omega_rms_deg_s")
    if len(est):
        err = np.degrees(est - gt)
        out.update(zip(names, [*np.sqrt(np.mean(err**2, axis=0)), np.sqrt(np.mean(np.sum(err**2, axis=1)))]))
    else:
        out.update(dict.fromkeys(names))
    tv = np.asarray(t)[frames]
    rpe = np.array([])
    if len(tv) > 1:
        tolerance = 0.5 * float(np.median(np.diff(tv)))
        j = np.clip(np.searchsorted(tv, tv + delta_s), 1, len(tv) - 1)
        j = np.where(np.abs(tv[j - 1] - (tv + delta_s)) < np.abs(tv[j] - (tv + delta_s)), j - 1, j)
        keep = (np.abs(tv[j] - (tv + delta_s)) <= tolerance) & (j > np.arange(len(tv)))
        i, j = np.flatnonzero(keep), j[keep]
        if len(i):
            rel_gt = np.swapaxes(R_gt[i], 1, 2) @ R_gt[j]
            rel_est = np.swapaxes(R_est[i], 1, 2) @ R_est[j]
            rpe = np.degrees(geodesic_angle(rel_gt, rel_est))
    out["rpe_pairs"] = int(len(rpe))
    out["rpe_1s_mean_deg"] = float(rpe.mean()) if len(rpe) else None
    out["rpe_1s_rmse_deg"] = float(np.sqrt(np.mean(rpe**2))) if len(rpe) else None
    return {k: (float(v) if isinstance(v, np.floating) else v) for k, v in out.items()}


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
    return RotationErrors(valid, R_gt, p_gt if len(ape) else np.empty((0, 3)), R_aligned, ape, span,
                          ground_truth_gap_limit_s(ground_truth.t, at))


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


def tum_aligned_rotations(estimate_tum: Path, groundtruth_tum: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(common timestamps [s], R_w_c ground truth, R_w_c estimate aligned at the first) of two
    TUM files; None if either is unreadable or they share no timestamp."""
    from eas_vo.io.tum import read_tum

    try:
        t_est, _, q_est = read_tum(estimate_tum)
        t_gt, _, q_gt = read_tum(groundtruth_tum)
    except (OSError, ValueError):
        return None
    common, i_est, i_gt = np.intersect1d(t_est, t_gt, return_indices=True)
    if len(common) == 0:
        return None
    R_gt = matrices_from_quats(q_gt[i_gt])
    R_aligned, _ = aligned_errors(R_gt, matrices_from_quats(q_est[i_est]))
    return common, R_gt, R_aligned


#: How far [s] run.time_offset_auto searches for the ground truth's time offset, either way.
OFFSET_SEARCH_S = 0.1


def estimate_time_offset(t: np.ndarray, edges, ground_truth: PoseSeries, search_s: float = OFFSET_SEARCH_S) -> float | None:
    """The offset [s] to add to frame times so that ground truth best explains the measured rotations.

    For a candidate offset d, each measured relative rotation R_i_j is compared with the
    ground truth's between t_i + d and t_j + d; the cost is the mean geodesic error [rad] of
    the best 80 % (robust to tracking failures). A 2 ms grid over [-search_s, search_s] is
    refined to 0.1 ms around its best point. None when it cannot be estimated: fewer than 5
    edges; ground truth spanning fewer than half of them (and 5) at every offset of the grid;
    or no clear best: an offset at either end of the search costs no more than the best
    plus two standard errors of that best cost (a still camera, identical frames, rotation
    at a constant rate: a flat cost; or a best fit on the search's edge, the true offset
    lying beyond it).
    """
    from scipy.spatial.transform import Rotation, Slerp

    t = np.asarray(t, dtype=float)
    edges = [e for e in edges if 0 <= e.i < len(t) and 0 <= e.j < len(t)]
    if len(edges) < 5:
        return None
    i = np.array([e.i for e in edges])
    j = np.array([e.j for e in edges])
    R_meas = np.stack([e.R_i_j for e in edges])
    slerp = Slerp(ground_truth.t, Rotation.from_quat(ground_truth.q_w_c))
    span = (ground_truth.t[0], ground_truth.t[-1])

    def kept_errors(offset: float) -> np.ndarray | None:
        """The best 80 % of the edges' errors [rad] at `offset`; None if too few edges have ground truth."""
        tt = t + offset
        use = (tt[i] >= span[0]) & (tt[j] <= span[1])
        if use.sum() < max(5, len(edges) // 2):
            return None
        R_i = slerp(tt[i[use]]).as_matrix()
        R_j = slerp(tt[j[use]]).as_matrix()
        errors = np.sort(geodesic_angle(np.swapaxes(R_i, 1, 2) @ R_j, R_meas[use]))
        return errors[: int(0.8 * len(errors))]

    def cost(offset: float) -> float:
        kept = kept_errors(offset)
        return np.inf if kept is None else float(kept.mean())

    coarse = np.arange(-search_s, search_s + 1e-9, 0.002)
    costs = np.array([cost(d) for d in coarse])
    if not np.isfinite(costs.min()):
        return None
    best = int(np.argmin(costs))
    kept = kept_errors(coarse[best])
    noise = 2 * kept.std(ddof=1) / np.sqrt(len(kept))
    if min(costs[0], costs[-1]) <= costs[best] + noise:
        return None
    fine = coarse[best] + np.arange(-0.002, 0.002 + 1e-9, 0.0001)
    return float(fine[np.argmin([cost(d) for d in fine])])


@dataclass(frozen=True)
class ImuAgreement:
    """How the gyro's frame-to-frame rotations agree with the tracker's.

    Attributes:
        R: the rotation that best maps the tracker's rotation vectors onto the gyro's, g = R v
            (the identity when the IMU's configured place on the rig is right).
        pairs: consecutive frame pairs compared (the gyro turned at least MIN_TURN_RAD), with
            the gyro on the clock of the last round (within 1 ms of clock_shift_s unless the
            rounds ran out).
        agreeing: those within half the gyro's rotation of R v.
        spread: the second singular value of the agreeing rotation vectors over the first: near
            0 when the camera turned about one axis only, and R is then free about that axis.
        clock_shift_s: the gyro read this much later [s] explains the agreeing pairs best (0
            when the images and the gyro's configured clock agree).
        shift_at_limit: the best shift lies on the edge of the last search (CLOCK_SEARCH_S
            around the previous estimate): the offset may be larger still.
        residual_rad, residual_unshifted_rad: the median |g - R v| [rad] over the agreeing
            pairs with the gyro read clock_shift_s later, and as configured.
        turned_sigma_deg: the standard deviation [deg] of R's angle about its least certain
            axis, from the agreeing pairs' scatter about the fit (_fit_sigma_deg): fewer pairs,
            smaller rotations or noisier images make it larger.
        mirrored: the fit is of the gyro's rates negated, -g = R v (its axes mirrored).
    """

    R: np.ndarray
    pairs: int
    agreeing: int
    spread: float
    clock_shift_s: float
    shift_at_limit: bool
    residual_rad: float
    residual_unshifted_rad: float
    turned_sigma_deg: float
    mirrored: bool = False

    @property
    def turned_deg(self) -> float:
        """How far [deg] the gyro's axes are turned from the images' (R's angle)."""
        return float(np.degrees(geodesic_angle(np.eye(3), self.R)))


#: Frame pairs over which the gyro turned less carry no direction to compare [rad] (0.5 deg).
MIN_TURN_RAD = np.radians(0.5)
#: How far around its last estimate the IMU's clock is searched [s], in 1 ms steps (about a
#: DAVIS frame interval), and how many times the fit and the search are redone at the new
#: estimate (the pairs that agree depend on the clock: a 30 ms error is under-read the first time).
CLOCK_SEARCH_S = 0.05
CLOCK_ROUNDS = 4


#: The gyro's rates negated are fitted only when its own fit is turned this much [deg] or more.
MIRROR_TRIED_DEG = 10.0


def imu_agreement(t: np.ndarray, edges, imu: ImuSeries) -> ImuAgreement | None:
    """Compare the rotation vectors of the consecutive edges (camera frame) with the gyro's
    over the same frame times [s] (`imu` in the camera frame, on the frames' clock): the
    rotation between them (_fit_axes) and the gyro's clock (_best_clock_shift), redone at the
    new clock until it moves less than 1 ms. None without 20 pairs to compare. The gyro's rates
    negated are fitted too where the fit is not near the identity (a mirrored axis convention,
    which no rotation undoes: a rotation by 180 deg explains the half of them about two axes),
    and kept, `mirrored`, where more pairs agree with them."""
    found = _agreement(t, edges, imu)
    if found is not None and found.turned_deg < MIRROR_TRIED_DEG:
        return found
    mirrored = _agreement(t, edges, ImuSeries(imu.t, imu.acc, -imu.gyro))
    if mirrored is not None and (found is None or mirrored.agreeing > found.agreeing):
        return replace(mirrored, mirrored=True)
    return found


def _agreement(t: np.ndarray, edges, imu: ImuSeries) -> ImuAgreement | None:
    """imu_agreement for the gyro's rates as they are."""
    steps = [e for e in edges if e.j == e.i + 1 and 0 <= e.i < len(t) - 1]
    t0 = np.array([t[e.i] for e in steps], float)
    t1 = np.array([t[e.j] for e in steps], float)
    v_all = matrix_to_rotvec(np.stack([e.R_i_j for e in steps])) if steps else np.empty((0, 3))
    turned = imu.turned_since_start()
    shift, found = 0.0, None
    for _ in range(CLOCK_ROUNDS):
        g = turned(t1 + shift) - turned(t0 + shift)
        keep = (t0 + shift >= imu.t[0]) & (t1 + shift <= imu.t[-1]) & (np.linalg.norm(g, axis=-1) >= MIN_TURN_RAD)
        if keep.sum() < 20:
            break
        v, g = v_all[keep], g[keep]
        R, agree = _fit_axes(v, g)
        if agree.sum() < 20:
            break
        best, limit, residual, unshifted = _best_clock_shift(t0[keep][agree], t1[keep][agree], v[agree] @ R.T, turned, imu, shift)
        singular = np.linalg.svd(v[agree], compute_uv=False)
        spread = float(singular[1] / max(singular[0], 1e-12))
        moved, shift = abs(best - shift), best
        found = ImuAgreement(R, len(v), int(agree.sum()), spread, best, limit, residual, unshifted,
                             _fit_sigma_deg(v[agree] @ R.T, g[agree]))
        if moved < 1e-3:
            break
    return found


def _fit_axes(v: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R with g = R v for rotation vectors v, g (N, 3): Kabsch on all, then twice on the pairs
    within half the gyro's rotation of the fit (robust to failed measurements and a few percent
    of scale); returns R and that agreeing mask."""
    from eas_vo.geometry.two_view import kabsch

    agree = np.ones(len(v), bool)
    for _ in range(3):
        R = kabsch(v[agree], g[agree])
        agree = np.linalg.norm(g - v @ R.T, axis=1) < 0.5 * np.linalg.norm(g, axis=1)
        if agree.sum() < 3:
            break
    return R, agree


def _fit_sigma_deg(u: np.ndarray, g: np.ndarray) -> float:
    """The standard deviation [deg] of a small rotation d in g = Exp(d) u + noise, about its least
    certain axis, for rotation vectors u (the fitted tracker's, (N, 3)) and g (the gyro's): the
    noise per axis from the median residual (|noise| of a 3-D Gaussian has median 1.538 sigma),
    the information sum(|u|^2 I - u u^T) / sigma^2 of the linearised fit."""
    sigma = np.median(np.linalg.norm(g - u, axis=1)) / 1.538
    information = np.sum(u * u) * np.eye(3) - u.T @ u
    smallest = np.linalg.eigvalsh(information)[0]
    return float(np.degrees(sigma / np.sqrt(smallest))) if smallest > 0 else float("inf")


def _best_clock_shift(t0: np.ndarray, t1: np.ndarray, expected: np.ndarray, turned, imu: ImuSeries,
                      around: float) -> tuple[float, bool, float, float]:
    """The shift d [s] of the gyro's clock (read at t + d) whose rotation vectors over frame
    times t0 < t1 (`turned`: ImuSeries.turned_since_start) best match `expected` (N, 3) [rad], by the median
    distance on a 1 ms grid within CLOCK_SEARCH_S of `around`, refined by a parabola. Returns
    d, whether it lies on the grid's edge, the median at d and the median at 0 (pairs the
    gyro covers at every shift only)."""
    span = CLOCK_SEARCH_S + abs(around)
    covered = (t0 - span >= imu.t[0]) & (t1 + span <= imu.t[-1])
    t0, t1, expected = t0[covered], t1[covered], expected[covered]
    if len(t0) < 20:
        return around, False, np.nan, np.nan

    def median(d: float) -> float:
        return float(np.median(np.linalg.norm(turned(t1 + d) - turned(t0 + d) - expected, axis=-1)))

    shifts = around + np.arange(-round(CLOCK_SEARCH_S * 1e3), round(CLOCK_SEARCH_S * 1e3) + 1) * 1e-3
    costs = np.array([median(d) for d in shifts])  # one shift at a time: memory stays O(pairs)
    k = int(np.argmin(costs))
    best = shifts[k]
    if 0 < k < len(shifts) - 1:
        curvature = costs[k - 1] - 2 * costs[k] + costs[k + 1]
        if curvature > 0:
            best += 0.5e-3 * (costs[k - 1] - costs[k + 1]) / curvature
    return float(best), k in (0, len(shifts) - 1), median(best), median(0.0)


# ----------------------------------------------------------------------------- external trajectories

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
ORIGIN_INSTEAD = "; to score the rotations alone (e.g. a rotation-only trajectory), align at the first pose: --align origin"


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
        raise ValueError(f"{len(i_gt)} estimate pose(s) within {max_diff_s} s of a ground-truth pose; "
                         f"{align} alignment needs at least {least}{instead}")
    p_gt, R_gt = ground_truth.p_w_c[i_gt], matrices_from_quats(ground_truth.q_w_c[i_gt])
    p_est, R_est = estimate.p_w_c[i_est], matrices_from_quats(estimate.q_w_c[i_est])
    if align == "origin":
        R_a = R_gt[0] @ R_est[0].T
        t_a, s = p_gt[0] - R_a @ p_est[0], 1.0
    else:
        similar = umeyama(p_est, p_gt, with_scale=True)
        if similar is None:
            raise ValueError(f"the positions of the {len(i_gt)} matched poses lie on a line or a point; "
                             f"{align} alignment needs them to span a plane{ORIGIN_INSTEAD}")
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below
            shape_error_m = np.linalg.norm(p_gt - similarity_transform(*similar, p_est, R_est)[0], axis=1)
        uncertainty = alignment_uncertainty(p_gt, shape_error_m, dof=7)
        if uncertainty > ALIGN_UNCERTAINTY_RAD:
            raise ValueError(f"the {len(i_gt)} matched positions fix the {align} alignment's rotation only to about "
                             f"{uncertainty:.2g} rad ({ALIGN_UNCERTAINTY_RAD:g} at most): they spread too little across "
                             f"their main direction for how far they miss the ground truth{ORIGIN_INSTEAD}")
        R_a, t_a, s = similar if align == "sim3" else umeyama(p_est, p_gt, with_scale=False)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below
        p_aligned, R_aligned = similarity_transform(R_a, t_a, s, p_est, R_est)
        ape = TrajectoryApe(estimate.t[i_est], R_a, t_a, s, np.linalg.norm(p_gt - p_aligned, axis=1),
                            geodesic_angle(R_gt, R_aligned))
        finite = np.isfinite(list(ape.summary().values())).all()
    if not (finite and s > 0):
        raise ValueError(f"positions up to {np.abs(p_est).max():.3g} m: the errors after {align} alignment "
                         "overflow floating point")
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
