"""Rotation-only solver, GRIC model choice and the flip guard, on random view pairs."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

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


@pytest.mark.parametrize("geometry", ["rotation", "auto"])
def test_flips_never_reach_the_result(geometry):
    """Small baselines make the essential matrix ill-posed; the guarded paths never flip."""
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(300):
        x_prev, x_cur, R = view_pair(rng, baseline_m=rng.choice([0.0, 0.002, 0.01, 0.03]))
        R_prev_cur = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", geometry).R_prev_cur
        worst = max(worst, np.degrees(geodesic_angle(R.T, R_prev_cur)))
    assert worst < 2.0, worst


def test_gric_prefers_the_model_the_data_has():
    rng = np.random.default_rng(3)
    chosen = {"pure": [], "parallax": []}
    for _ in range(20):
        x_prev, x_cur, _ = view_pair(rng, noise_px=0.3)
        chosen["pure"].append(rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "auto").model)
        x_prev, x_cur, R = view_pair(rng, baseline_m=0.3, depth=(1.0, 3.0), noise_px=0.3)
        R_prev_cur, _, model, _ = rotation_from_correspondences(x_prev, x_cur, 1.0 / F_PX, 0.999, "usac", "auto")
        chosen["parallax"].append(model)
        if model == "essential":
            assert np.degrees(geodesic_angle(R.T, R_prev_cur)) < 0.5
    assert chosen["pure"].count("rotation") >= 16 and chosen["parallax"].count("essential") >= 16, chosen
