"""The event-rotation benchmark's protocol (CMax-SLAM's) on trajectories with known answers:
the manifold Gaussian against a computation by hand, the one-pose alignment, the RMS angle and
the 1 s relative error."""

import numpy as np
import pytest

from eas_vo.evaluation.rotation_protocol import (
    ALIGN_AT_S,
    RELATIVE_SPAN_S,
    SMOOTHING_SIGMA_S,
    SMOOTHING_SPAN_S,
    score,
    smooth_rotations,
)
from eas_vo.geometry.rotations import quats_from_matrices, rotvec_to_matrix
from eas_vo.types import PoseSeries

AXIS = np.array([0.48, -0.6, 0.64])  # a unit vector off every camera axis


def series(t, R) -> PoseSeries:
    return PoseSeries(np.asarray(t, float), np.zeros((len(t), 3)), quats_from_matrices(R))


def about(axis, angles) -> np.ndarray:
    return rotvec_to_matrix(np.outer(angles, axis))


def test_the_gaussian_of_a_turn_about_one_axis_is_the_gaussian_of_its_angle_by_hand():
    # about a fixed axis the manifold mean is the angles' weighted mean: computed here pose by pose
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.006, 400))  # 200 Hz with jitter
    angle = 3.0 * np.sin(2.1 * t) + 0.8 * t**2  # several radians: far beyond any wrap
    sigma = 0.05
    got = smooth_rotations(t, about(AXIS, angle), sigma, truncate=3.0)
    for k in (0, 7, 150, 399):
        near = np.abs(t - t[k]) <= 3 * sigma
        w = np.exp(-0.5 * ((t[near] - t[k]) / sigma) ** 2)
        by_hand = np.sum(w * angle[near]) / np.sum(w)
        assert np.abs(got[k] - about(AXIS, [by_hand])[0]).max() < 1e-9


def test_the_gaussian_leaves_a_constant_rate_spin_alone_through_many_turns():
    # 2.5 turns a second: rotation vectors about one reference would wrap at pi and break
    t = np.arange(0, 2, 0.005)
    R = about(AXIS, 2.5 * 2 * np.pi * t)
    got = smooth_rotations(t, R, 0.05)
    interior = (t > 0.15) & (t < t[-1] - 0.15)
    assert np.abs(got[interior] - R[interior]).max() < 1e-9
    assert np.abs(got[0] - R[0]).max() > 1e-3  # at the ends the window is one-sided: it lags


def test_the_gaussian_off_one_axis_agrees_with_its_tangent_average_by_hand():
    rng = np.random.default_rng(8)
    t = np.arange(0, 1, 0.005)
    R = rotvec_to_matrix(np.cumsum(rng.normal(0, 0.05, (len(t), 3)), axis=0))
    sigma, k = 0.02, 100
    near = np.flatnonzero(np.abs(t - t[k]) <= 3 * sigma + 1e-6)  # both ends of the window: 12 poses either side
    w = np.exp(-0.5 * ((t[near] - t[k]) / sigma) ** 2)
    from scipy.spatial.transform import Rotation

    logs = np.stack([Rotation.from_matrix(R[k].T @ R[j]).as_rotvec() for j in near])
    by_hand = R[k] @ Rotation.from_rotvec(w @ logs / w.sum()).as_matrix()
    assert np.abs(smooth_rotations(t, R, sigma, truncate=3.0)[k] - by_hand).max() < 1e-9
    assert np.array_equal(smooth_rotations(t, R, 0.0), R)


def gt_and_drifting_estimate(drift_rad_s: float, offset=None):
    """Ground truth spinning about AXIS; an estimate that turns drift_rad_s faster about the same
    axis, seen from a world rotated by `offset`; times from 100 s (a clock not at zero)."""
    t = 100.0 + np.arange(0, 12.0001, 0.005)
    gt = series(t, about(AXIS, 0.7 * (t - 100)))
    offset = np.eye(3) if offset is None else offset
    est_t = t[::9]  # about 22 Hz, as DAVIS frames
    est = series(est_t, offset @ about(AXIS, (0.7 + drift_rad_s) * (est_t - 100)))
    return gt, est


def test_an_estimate_equal_up_to_one_rotation_scores_zero():
    gt, est = gt_and_drifting_estimate(0.0, offset=rotvec_to_matrix([0.3, -1.2, 2.0]))
    s = score(est, gt, start_s=100.0, duration_s=10.0, sigma_s=0.0)
    m = s.summary()
    assert m["absolute_rms_deg"] < 1e-9 and m["relative_rms_deg_s"] < 1e-9
    assert s.t[0] == 0.0 and s.t[-1] <= 10.0 and m["spans_scored"] == 91  # 0, 0.1, ..., 9.0


def test_a_drift_about_the_motion_axis_has_known_absolute_and_relative_errors():
    drift = np.radians(2.0)  # 2 deg/s too fast
    gt, est = gt_and_drifting_estimate(drift, offset=rotvec_to_matrix([1.0, 0.2, -0.4]))
    s = score(est, gt, start_s=100.0, duration_s=10.0, sigma_s=0.0)
    # aligned at 1 s: the error at time x is 2 deg/s * |x - 1 s|
    assert np.allclose(s.error_deg, 2.0 * np.abs(s.t - ALIGN_AT_S), atol=1e-9)
    by_hand = np.sqrt(np.mean((2.0 * np.abs(s.t - ALIGN_AT_S)) ** 2))
    assert s.summary()["absolute_rms_deg"] == pytest.approx(by_hand, abs=1e-9)
    # over any 1 s span the relative rotations differ by 2 degrees: 2 deg/s
    assert np.allclose(s.relative_deg_s, 2.0 * RELATIVE_SPAN_S / RELATIVE_SPAN_S, atol=1e-9)


def test_the_score_does_not_depend_on_the_clocks_origin():
    gt, est = gt_and_drifting_estimate(np.radians(1.0))
    a = score(est, gt, start_s=100.0, duration_s=10.0).summary()
    shift = 1.7e9  # a Unix clock
    moved = [PoseSeries(x.t + shift, x.p_w_c, x.q_w_c) for x in (est, gt)]
    b = score(*moved, start_s=100.0 + shift, duration_s=10.0).summary()
    for key in ("absolute_rms_deg", "relative_rms_deg_s"):
        assert b[key] == pytest.approx(a[key], rel=1e-6)


def test_smoothing_the_ground_truth_changes_a_wobbling_one_by_the_filters_known_gain():
    # a 10 Hz wobble of amplitude A about AXIS at 200 Hz: the protocol's Gaussian (11 taps, sigma
    # 2 samples) passes about exp(-(2 pi f sigma)^2 / 2) of it, 82 %
    t = np.arange(0, 12, 0.005)
    A, f = np.radians(5.0), 10.0
    gt = series(t, about(AXIS, A * np.sin(2 * np.pi * f * t)))
    still = series(t[::9], np.repeat(np.eye(3)[None], len(t[::9]), axis=0))
    s = score(still, gt, start_s=0.0, duration_s=10.0)  # aligned at 1 s, a zero of the wobble
    lags, sigma = 0.005 * np.arange(-5, 6), 0.01  # MATLAB's gausswin(11): the 50 ms window
    w = np.exp(-0.5 * (lags / sigma) ** 2)
    gain = np.sum(w * np.cos(2 * np.pi * f * lags)) / np.sum(w)
    assert gain == pytest.approx(np.exp(-0.5 * (2 * np.pi * f * sigma) ** 2), rel=0.02)  # the continuous Gaussian's
    inside = (s.t > 0.2) & (s.t < 9.8)
    expected = np.degrees(A) * gain * np.abs(np.sin(2 * np.pi * f * s.t[inside]))
    assert np.allclose(s.error_deg[inside], expected, atol=1e-9)


def test_the_window_is_the_papers_50_ms_span_of_gaussian_taps():
    assert SMOOTHING_SPAN_S == 0.05 and SMOOTHING_SIGMA_S == pytest.approx(0.01)  # gausswin(11) at 200 Hz


def test_an_estimate_that_misses_the_alignment_time_is_refused():
    gt, est = gt_and_drifting_estimate(0.0)
    late = PoseSeries(est.t[est.t > 102], est.p_w_c[est.t > 102], est.q_w_c[est.t > 102])
    with pytest.raises(ValueError, match="does not cover the alignment time, 1 s after the start"):
        score(late, gt, start_s=100.0)
