"""Rotation-only solver, GRIC model choice and the flip guard, on random view pairs."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.geometry import two_view
from eas_vo.geometry.rotations import geodesic_angle
from eas_vo.geometry.two_view import bearings, kabsch, rotation_from_correspondences, rotation_ransac

F_PX = 200.0


def view_pair(rng, n=200, rot_std_rad=0.03, baseline_m=0.0, depth=(2.0, 5.0), noise_px=0.5, outliers=0.1):
    """Matched normalised points of two views: x_cur ~ R_cur_prev X + t. Returns (x_prev, x_cur, R_cur_prev)."""
    x_prev = rng.uniform(-0.55, 0.55, (n, 2))
    X = np.column_stack([x_prev, np.ones(n)]) * rng.uniform(*depth, (n, 1))
    R = Rotation.from_rotvec(rng.normal(0, rot_std_rad, 3)).as_matrix()
    t = rng.normal(size=3)
    t *= baseline_m / max(np.linalg.norm(t), 1e-12)
    Xc = X @ R.T + t
    x_cur = Xc[:, :2] / Xc[:, 2:]
    x_prev = x_prev + rng.normal(0, noise_px / F_PX, x_prev.shape)
    x_cur = x_cur + rng.normal(0, noise_px / F_PX, x_cur.shape)
    bad = rng.random(n) < outliers
    x_cur[bad] = rng.uniform(-0.55, 0.55, (bad.sum(), 2))
    return x_prev, x_cur, R


def test_kabsch_recovers_an_exact_rotation():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(10, 3))
    R = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    np.testing.assert_allclose(kabsch(a, a @ R.T), R, atol=1e-12)


def test_two_point_hypotheses_are_kabsch_and_count_inliers():
    """The compiled closed form against numpy's SVD-based Kabsch on random pairs; its inlier
    counts against a direct angle test; a pair of parallel bearings defines nothing."""
    rng = np.random.default_rng(3)
    x_prev, x_cur, _ = view_pair(rng, outliers=0.3)
    f_prev, f_cur = bearings(x_prev), bearings(x_cur)
    pairs = rng.integers(0, len(f_prev), (64, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    f_prev[pairs[0, 1]] = f_prev[pairs[0, 0]]  # parallel in the previous view
    threshold = 1.5 / F_PX
    R, counts = two_view._two_point_hypotheses(f_prev, f_cur, pairs, np.cos(threshold))
    np.testing.assert_allclose(R[1:], kabsch(f_prev[pairs[1:]], f_cur[pairs[1:]]), atol=1e-12)
    angles = np.arccos(np.clip(np.einsum("kij,nj,ni->kn", R[1:], f_prev, f_cur), -1, 1))
    np.testing.assert_array_equal(counts[1:], (angles < threshold).sum(axis=1))
    assert counts[0] == 0 and not R[0].any()


@pytest.mark.parametrize("outliers,samples", [(0.0, 32), (0.7, 96)])
def test_ransac_draws_as_many_samples_as_its_inlier_ratio_needs(outliers, samples):
    """log(1 - 0.999) / log(1 - w^2) samples: 1 batch of 32 when every point agrees, 73
    samples (3 batches) when 30 % do."""
    rng = np.random.default_rng(4)
    x_prev, x_cur, R = view_pair(rng, n=400, noise_px=0.0, outliers=0.0)
    x_cur[: int(outliers * 400)] = rng.uniform(-0.55, 0.55, (int(outliers * 400), 2))
    f_prev, f_cur = bearings(x_prev), bearings(x_cur)
    pairs = np.random.default_rng(0).integers(0, 400, (256, 2))
    _, count, drawn = two_view._best_two_point_rotation(f_prev, f_cur, pairs, np.cos(1.0 / F_PX), 0.999, 32)
    assert drawn == samples and count >= 400 - int(outliers * 400)
    R_est, mask = rotation_ransac(f_prev, f_cur, 1.0 / F_PX, confidence=0.999)
    assert np.degrees(geodesic_angle(R, R_est)) < 0.01 and mask.sum() >= 400 - int(outliers * 400)


def test_rotation_only_solver_is_accurate_on_noisy_pure_rotations():
    rng = np.random.default_rng(1)
    errors = []
    for _ in range(200):
        x_prev, x_cur, R = view_pair(rng)
        R_est, mask = rotation_ransac(bearings(x_prev), bearings(x_cur), 1.5 / F_PX)
        errors.append(np.degrees(geodesic_angle(R, R_est)))
        assert mask.sum() > 0.7 * len(mask)  # 10 % outliers, and the noise tail past 1.5 px
    assert np.median(errors) < 0.05, np.median(errors)
    assert np.max(errors) < 0.2


@pytest.mark.parametrize("geometry", ["rotation", "auto", "essential", "homography"])
def test_flips_never_reach_the_result(geometry):
    """Small baselines make the essential matrix ill-posed (cheirality undecided); no geometry
    flips: the essential matrix's rotation is the one of its twisted pair that explains the
    bearings."""
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(300):
        x_prev, x_cur, R = view_pair(rng, baseline_m=rng.choice([0.0, 0.002, 0.01, 0.03]))
        R_prev_cur = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", geometry).R_prev_cur
        worst = max(worst, np.degrees(geodesic_angle(R.T, R_prev_cur)))
    assert worst < 2.0, worst


@pytest.mark.parametrize("geometry", ["essential", "auto", "homography", "rotation"])
def test_views_without_motion_are_the_identity(geometry):
    """Identical points (a still camera, a repeated frame) and points that moved by a tenth of
    the inlier threshold: no parallax determines no essential matrix; every geometry measures
    the identity, never the half turn of a degenerate decomposition."""
    for seed in range(20):
        rng = np.random.default_rng(seed)
        x_prev = rng.uniform(-0.55, 0.55, (int(rng.integers(20, 500)), 2))
        for x_cur in (x_prev.copy(), x_prev + rng.normal(0, 0.1 / F_PX, x_prev.shape)):
            found = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", geometry)
            assert found is not None and geodesic_angle(np.eye(3), found.R_prev_cur) < 0.2 / F_PX, (seed, found)


def test_an_essential_matrix_fitted_to_small_flow_does_not_turn_auto_by_its_rotation():
    """A slow turn (about 1 px of flow) seen through keypoints with 1 px of noise: the
    five-point fit can trade the rotation for a translation whose parallax nearly cancels it,
    turning the bearings further than they moved; `auto` then measures rotation-only, and no
    pair is off by the calibration's cut for a wrong measurement (3.5 px: 1 degree here)."""
    worst = 0.0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        x_prev, x_cur, R = view_pair(rng, n=40, rot_std_rad=0.004, noise_px=1.0, outliers=0.0)
        found = rotation_from_correspondences(x_prev, x_cur, 2.0 / F_PX, 0.999, "usac", "auto")
        worst = max(worst, geodesic_angle(R.T, found.R_prev_cur))
    assert worst < 3.5 / F_PX, np.degrees(worst)


def test_gric_prefers_the_model_the_data_has():
    rng = np.random.default_rng(3)
    chosen = {"pure": [], "parallax": []}
    for _ in range(20):
        x_prev, x_cur, _ = view_pair(rng, noise_px=0.3)
        chosen["pure"].append(rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "auto").model)
        x_prev, x_cur, R = view_pair(rng, baseline_m=0.3, depth=(1.0, 3.0), noise_px=0.3)
        R_prev_cur, _, model, *_ = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "auto")
        chosen["parallax"].append(model)
        if model == "essential":
            assert np.degrees(geodesic_angle(R.T, R_prev_cur)) < 0.5
    assert chosen["pure"].count("rotation") >= 16 and chosen["parallax"].count("essential") >= 16, chosen


def plane_view_pair(rng, t_m, tilt_deg, n=200, noise_px=0.2, outliers=0.1):
    """Matched normalised points on a plane 1 m away (its normal tilted `tilt_deg` about x),
    seen from two places `t_m` [m] (second view in the first's frame) and 8 degrees of rotation
    apart. Returns (x_prev, x_cur, R_cur_prev)."""
    x_prev = rng.uniform(-0.55, 0.55, (n, 2))
    normal = Rotation.from_euler("x", tilt_deg, degrees=True).apply([0.0, 0.0, 1.0])  # n^T X = 1 m
    X = np.column_stack([x_prev, np.ones(n)])
    X /= (X @ normal)[:, None]
    R = Rotation.from_rotvec(np.radians(8) * np.array([0.6, 0.8, 0.0])).as_matrix()
    Xc = (X - np.asarray(t_m)) @ R.T
    x_cur = Xc[:, :2] / Xc[:, 2:] + rng.normal(0, noise_px / F_PX, (n, 2))
    x_prev = x_prev + rng.normal(0, noise_px / F_PX, (n, 2))
    bad = rng.random(n) < outliers
    x_cur[bad] = rng.uniform(-0.55, 0.55, (bad.sum(), 2))
    return x_prev, x_cur, R


@pytest.mark.parametrize("direction", [(1, 0, 0), (0.8, 0, 0.6), (0, 0.6, -0.8), (0, 0, 1)])
@pytest.mark.parametrize("tilt_deg", [0, 20, 40, 60])
def test_a_homography_keeps_a_planes_parallax_out_of_the_rotation_or_measures_nothing(direction, tilt_deg):
    """5 cm (sideways, forward, backward) in front of a plane 1 m away, LK-like noise (0.2 px):
    rotation-only turns the parallax into rotation; the homography's rotation is within 0.2
    degrees whenever it gives one, and when the true decomposition and its dual (normal along
    the translation) both fit, the result is the rotation-only one: never the dual."""
    rng = np.random.default_rng(5)
    t_m = 0.05 * np.asarray(direction, float)
    measured, rotation_only = [], []
    for _ in range(5):
        x_prev, x_cur, R = plane_view_pair(rng, t_m, tilt_deg)
        found = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "homography")
        rotation = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "rotation")
        rotation_only.append(np.degrees(geodesic_angle(R.T, rotation.R_prev_cur)))
        if found.model == "homography":
            measured.append(np.degrees(geodesic_angle(R.T, found.R_prev_cur)))
        else:
            np.testing.assert_allclose(found.R_prev_cur, rotation.R_prev_cur)
    assert all(error < 0.2 for error in measured), measured
    if direction == (1, 0, 0) and tilt_deg < 60:  # sideways: the dual puts half the points behind
        assert len(measured) == 5 and np.median(rotation_only) > 2.0, (measured, rotation_only)


def test_exact_points_never_give_a_nan_rotation():
    """Noiseless inliers (and 10 % outliers) can decompose into NaN solutions (OpenCV: 8 of
    these 112 pairs); none is taken. The homography's rotation is the true one or a dual
    within the inlier threshold of it (1 px: 0.29 degrees)."""
    rng = np.random.default_rng(0)
    for direction in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0.8, 0, 0.6), (0, 0.6, -0.8), (0.6, 0.8, 0), (0.6, 0.6, 0.53)]:
        for tilt_deg in (0, 20, 40, 60):
            for _ in range(4):
                t_m = 0.03 * np.asarray(direction)
                x_prev, x_cur, R = plane_view_pair(rng, t_m, tilt_deg, noise_px=0.0)
                found = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "homography")
                assert np.isfinite(found.R_prev_cur).all()
                if found.model == "homography":
                    assert geodesic_angle(R.T, found.R_prev_cur) <= 1.0 / F_PX


def test_a_homography_of_a_pure_rotation_is_its_rotation():
    """No baseline: H = R, the normal undetermined; within 0.2 degrees (the rotation-only
    estimate when no decomposition puts the points in front of both views)."""
    rng = np.random.default_rng(6)
    for _ in range(10):
        x_prev, x_cur, R = plane_view_pair(rng, np.zeros(3), 20)
        found = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "homography")
        assert np.degrees(geodesic_angle(R.T, found.R_prev_cur)) < 0.2


@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_a_homography_needs_four_points(n):
    rng = np.random.default_rng(7)
    x_prev, x_cur, _ = plane_view_pair(rng, np.array([0.05, 0, 0]), 0, n=n, outliers=0.0)
    assert two_view.homography_rotation(x_prev, x_cur, 1.0 / F_PX, 0.999) is None


@pytest.mark.parametrize("geometry", ["rotation", "essential", "auto", "homography"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_points_measure_nothing(geometry, bad):
    """No NaN rotation reaches a tracker: points that are all non-finite give no model."""
    x_prev, x_cur, _ = view_pair(np.random.default_rng(8), n=50)
    x_prev[:] = bad
    with np.errstate(invalid="ignore"):
        assert rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", geometry) is None
