"""Known answers for the covariance of a two-view rotation: over many draws of Gaussian pixel
noise of known sigma, the NEES (normalised estimation error squared, delta^T Sigma^-1 delta) of
the measured rotation has the mean of a chi-square with 3 degrees of freedom, 3, when the
covariance is right. These are the linearisation's known answers, so they hold with
covariance.SCALE (the factors fitted on real tracking, whose errors are not independent) set
to 1; the last test checks the factors are applied."""

import numpy as np
import pytest

from eas_vo.geometry import covariance
from eas_vo.geometry.covariance import UNDETERMINED_VARIANCE, essential_covariance, rotation_only_covariance, skew
from eas_vo.geometry.rotations import matrix_to_rotvec, rotvec_to_matrix
from eas_vo.geometry.two_view import bearings, rotation_from_correspondences

FOCAL_PX = 200.0
HALF_FOV = np.tan(np.radians(30.0))  # a 60 degree field of view
R_CUR_PREV = rotvec_to_matrix([0.02, -0.03, 0.01])


@pytest.fixture(autouse=True)
def unscaled(monkeypatch):
    """The linearisation as it is: no factor (covariance.SCALE) on any covariance."""
    factors = dict(covariance.SCALE)
    monkeypatch.setattr(covariance, "SCALE", {})
    return factors


def pair(rng, n, noise_px, translation):
    """Normalised points (n, 2) of one scene in two views (the second turned by R_CUR_PREV and
    moved by `translation`), each with Gaussian noise of `noise_px` per axis."""
    X = np.column_stack([rng.uniform(-HALF_FOV, HALF_FOV, (n, 2)), np.ones(n)]) * rng.uniform(2.0, 5.0, (n, 1))
    X_cur = X @ R_CUR_PREV.T + translation
    noise = noise_px / FOCAL_PX
    return (
        X[:, :2] / X[:, 2:] + rng.normal(0, noise, (n, 2)),
        X_cur[:, :2] / X_cur[:, 2:] + rng.normal(0, noise, (n, 2)),
    )


def nees(geometry, method, n, translation, draws=500, outliers=0):
    rng = np.random.default_rng(1)
    values = []
    for _ in range(draws):
        x_prev, x_cur = pair(rng, n, 0.2, translation)
        x_cur[:outliers] += rng.uniform(-0.1, 0.1, (outliers, 2))  # 20 px away: outliers
        found = rotation_from_correspondences(x_prev, x_cur, 1.0 / FOCAL_PX, 0.999, "usac", geometry, method)
        assert found.model == geometry
        delta = matrix_to_rotvec(found.R_prev_cur.T @ R_CUR_PREV.T)  # R_true = R_est Exp(delta)
        values.append(delta @ np.linalg.solve(found.covariance, delta))
    return float(np.mean(values))


@pytest.mark.parametrize("method", ["information", "bootstrap"])
def test_the_rotation_only_covariance_is_consistent(method):
    """A pure rotation, 0.2 px noise, 150 points: mean NEES within 10 % of 3."""
    assert nees("rotation", method, 150, np.zeros(3)) == pytest.approx(3.0, rel=0.1)


@pytest.mark.parametrize("method, tolerance", [("information", 0.1), ("bootstrap", 0.15)])
def test_the_five_point_covariance_is_consistent(method, tolerance):
    """A 30 cm move at 2-5 m, 0.2 px noise, 400 points: mean NEES within 10 % of 3 (the
    translation marginalised out). With 150 points it is 3.4-3.5: the five-point estimate is
    not quite the least-squares optimum the linearisation is taken about. The bootstrap's
    (3.36) is further off by its own sampling: a covariance from 200 draws inflates the NEES
    by about 2 % and its variance is itself uncertain by 10 %."""
    found = nees("essential", method, 400, np.array([0.3, 0.0, 0.05]), draws=500)
    assert found == pytest.approx(3.0, rel=tolerance)


def test_a_pair_with_outliers_is_consistent_on_its_inliers():
    """A fifth of the correspondences 20 px off: the covariance, from the inliers, still holds."""
    assert nees("rotation", "information", 150, np.zeros(3), draws=300, outliers=30) == pytest.approx(3.0, rel=0.15)


def test_a_narrow_field_of_view_measures_the_turn_about_its_optical_axis_worst():
    """The information about the optical axis is sum (x^2 + y^2) / (1 + x^2 + y^2) over the
    points, about the other axes about n: within a 60 degree field of view the roll's sigma is
    over twice the pan's and tilt's, and it shrinks as the field widens."""
    rng = np.random.default_rng(3)

    def sigmas(half_fov_deg):
        half = np.tan(np.radians(half_fov_deg))
        f = bearings(rng.uniform(-half, half, (200, 2)))
        return np.sqrt(np.diag(rotation_only_covariance(np.eye(3), f, f, 1.0 / FOCAL_PX)))

    narrow, wide = sigmas(30.0), sigmas(60.0)
    assert narrow[2] > 2.0 * max(narrow[:2]), narrow
    assert wide[2] / max(wide[:2]) < narrow[2] / max(narrow[:2])


def test_the_information_matches_the_closed_form():
    """Rotation-only information: sum (I - b b^T) / sigma^2, b the rotated bearings."""
    rng = np.random.default_rng(4)
    f = bearings(rng.uniform(-0.5, 0.5, (50, 2)))
    sigma = 0.002
    expected = np.linalg.inv(sum(np.eye(3) - np.outer(b, b) for b in f @ R_CUR_PREV.T) / sigma**2)
    got = rotation_only_covariance(R_CUR_PREV, f, f @ R_CUR_PREV.T, sigma)
    np.testing.assert_allclose(got, expected, rtol=1e-9)


def test_too_few_points_give_an_undetermined_covariance():
    f = bearings(np.zeros((1, 2)))
    for method in ("information", "bootstrap"):
        np.testing.assert_array_equal(
            rotation_only_covariance(np.eye(3), f, f, 0.01, method), UNDETERMINED_VARIANCE * np.eye(3)
        )


def test_skew_is_the_cross_product():
    v, w = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -4.0])
    np.testing.assert_allclose(skew(v) @ w, np.cross(v, w))
    np.testing.assert_allclose(skew(np.stack([v, w]))[1] @ v, np.cross(w, v))


@pytest.mark.parametrize("method", ["information", "bootstrap"])
def test_every_covariance_is_multiplied_by_its_factor(monkeypatch, unscaled, method):
    """covariance.SCALE multiplies the rotation-only (and homography) model's covariance by its
    `rotation` factor and the five-point model's by its `essential` one."""
    rng = np.random.default_rng(5)
    x_prev, x_cur = pair(rng, 60, 0.3, np.array([0.3, 0.0, 0.05]))
    f_prev, f_cur = bearings(x_prev), bearings(x_cur)
    E = skew(np.array([0.3, 0.0, 0.05]) / np.linalg.norm([0.3, 0.0, 0.05])) @ R_CUR_PREV
    plain = (
        rotation_only_covariance(R_CUR_PREV, f_prev, f_cur, 0.001, method),
        essential_covariance(E, R_CUR_PREV, x_prev, x_cur, 0.001, method),
    )
    monkeypatch.setattr(covariance, "SCALE", unscaled)
    scaled = (
        rotation_only_covariance(R_CUR_PREV, f_prev, f_cur, 0.001, method),
        essential_covariance(E, R_CUR_PREV, x_prev, x_cur, 0.001, method),
    )
    for got, expected, family in zip(scaled, plain, ("rotation", "essential")):
        np.testing.assert_allclose(got, unscaled[(method, family)] * expected, rtol=1e-9)
