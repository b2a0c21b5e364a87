"""Errors of the motion rather than the pose: angular velocity per frame interval and the relative
rotation error (RPE) over a fixed time span."""

from __future__ import annotations

import numpy as np

from eas_vo.evaluation.ape import RotationErrors
from eas_vo.geometry.rotations import geodesic_angle, matrix_to_rotvec

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
