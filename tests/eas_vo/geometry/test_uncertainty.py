"""The chain's propagated covariance against hand computations and Monte Carlo; sigmas per axis
and per Euler angle."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.geometry.rotations import euler_zyx_deg, matrix_to_rotvec, rotvec_to_matrix
from eas_vo.geometry.uncertainty import (
    UNDETERMINED_VARIANCE,
    axis_sigmas,
    chain_covariance,
    consecutive_steps,
    euler_sigmas_deg,
    largest_sigma,
)
from eas_vo.types import RelativeRotation


def random_covariance(rng, scale_rad=0.01):
    A = rng.normal(0, scale_rad, (3, 3))
    return A @ A.T + (0.1 * scale_rad) ** 2 * np.eye(3)


def test_identity_steps_of_one_covariance_add_up():
    """Sigma_k = k Sigma when every step is the identity with covariance Sigma."""
    Sigma = random_covariance(np.random.default_rng(0))
    edges = [RelativeRotation(k - 1, k, np.eye(3), 100, covariance=Sigma) for k in range(1, 8)]
    out = chain_covariance(8, edges)
    for k in range(8):
        np.testing.assert_allclose(out[k], k * Sigma, rtol=1e-12, atol=1e-18)


def test_a_step_turns_the_earlier_uncertainty_into_the_new_frame():
    """A 90 deg turn about z: the first frame's uncertainty about x is the second frame's about
    y (R^T Sigma R), the step's own added in the new frame."""
    R = rotvec_to_matrix([0, 0, np.pi / 2])  # frame 2's y axis is frame 1's -x
    first = np.diag([4e-4, 1e-4, 9e-4])
    second = np.diag([1e-6, 2e-6, 3e-6])
    edges = [RelativeRotation(0, 1, np.eye(3), covariance=first), RelativeRotation(1, 2, R, covariance=second)]
    out = chain_covariance(3, edges)
    np.testing.assert_allclose(out[1], first)
    np.testing.assert_allclose(out[2], np.diag([1e-4, 4e-4, 9e-4]) + second, atol=1e-15)


def test_the_chain_takes_the_steps_the_rotations_take():
    """Skip and loop edges beyond j = i + 1 carry nothing; a consecutive edge given twice counts
    once (the last), as chain_rotations multiplies it."""
    Sigma = 1e-4 * np.eye(3)
    edges = [
        RelativeRotation(0, 1, np.eye(3), covariance=Sigma),
        RelativeRotation(0, 2, np.eye(3), covariance=100 * Sigma),  # a skip edge
        RelativeRotation(1, 2, np.eye(3), covariance=Sigma),
        RelativeRotation(1, 2, np.eye(3), covariance=3 * Sigma),  # the last one counts
    ]
    assert consecutive_steps(edges)[2] is edges[3]
    np.testing.assert_allclose(chain_covariance(3, edges)[2], 4 * Sigma)


def test_a_frame_without_a_step_grows_by_the_neighbouring_turn_and_never_without_bound():
    """An unmeasured frame (kept at the previous rotation) adds the squared turn of the step
    before it on every axis; before the first measured step, that step's; a step without a
    finite covariance its own turn. Without any step: UNDETERMINED_VARIANCE a frame."""
    Sigma = 1e-6 * np.eye(3)
    turn = 0.02
    R = rotvec_to_matrix([0, turn, 0])
    edges = [
        RelativeRotation(1, 2, R, covariance=Sigma),  # frame 1 has no step; frame 3 none either
        RelativeRotation(3, 4, rotvec_to_matrix([0.05, 0, 0])),  # no inliers: an infinite covariance
    ]
    out = chain_covariance(5, edges)
    np.testing.assert_allclose(out[1], turn**2 * np.eye(3))  # the first measured step's turn, before it
    np.testing.assert_allclose(out[2], R.T @ out[1] @ R + Sigma, atol=1e-15)
    np.testing.assert_allclose(out[3], out[2] + turn**2 * np.eye(3), atol=1e-15)  # the step before it
    R4 = edges[1].R_i_j
    np.testing.assert_allclose(out[4], R4.T @ out[3] @ R4 + 0.05**2 * np.eye(3), atol=1e-15)  # its own turn
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(chain_covariance(3, [])[2], 2 * UNDETERMINED_VARIANCE * np.eye(3))


def test_the_propagation_matches_monte_carlo():
    """Steps perturbed by their covariance (right, in the later frame) 2000 times: the spread of
    the final rotation about the chained one is the propagated covariance (first order: noise
    of a few tenths of a degree), and not the same covariance taken in the world frame (a left
    perturbation): each step's noise lies mostly about its own x axis, and the steps turn."""
    rng = np.random.default_rng(1)
    n = 12
    steps = rotvec_to_matrix(rng.normal(0, 0.3, (n - 1, 3)))
    cov = np.diag([0.006, 0.002, 0.001]) ** 2
    edges = [RelativeRotation(k - 1, k, steps[k - 1], 100, covariance=cov) for k in range(1, n)]
    predicted = chain_covariance(n, edges)[-1]
    R_hat = np.linalg.multi_dot(list(steps))
    draws = 2000
    R_true = np.tile(np.eye(3), (draws, 1, 1))
    for step in steps:
        R_true = R_true @ step @ rotvec_to_matrix(rng.multivariate_normal(np.zeros(3), cov, draws))
    delta = matrix_to_rotvec(R_hat.T @ R_true)  # R_true = R_hat Exp(delta)
    sample = np.cov(delta.T)
    assert np.linalg.norm(sample - predicted) < 0.1 * np.linalg.norm(predicted)
    nees = np.einsum("ni,ij,nj->n", delta, np.linalg.inv(predicted), delta)
    assert nees.mean() == pytest.approx(3.0, abs=0.2)  # the chi-square(3) mean; its standard error is 0.055
    world = R_hat @ predicted @ R_hat.T
    assert np.linalg.norm(sample - world) > 0.3 * np.linalg.norm(predicted)


def test_sigmas_per_axis_and_along_the_worst_axis():
    cov = np.array([[4.0, 0, 0], [0, 1.0, 0.5], [0, 0.5, 1.0]]) * 1e-4
    np.testing.assert_allclose(axis_sigmas(cov), [0.02, 0.01, 0.01])
    assert largest_sigma(cov) == pytest.approx(0.02)
    np.testing.assert_allclose(largest_sigma(np.stack([cov, cov / 4])), [0.02, 0.01])


def test_euler_sigmas_follow_the_angles():
    """At the identity roll, pitch and yaw are the turns about the camera's x, y and z; elsewhere
    the Jacobian mixes them, as the spread of the angles of sampled perturbations shows."""
    cov = np.diag([1e-4, 4e-4, 9e-4])
    np.testing.assert_allclose(euler_sigmas_deg(np.eye(3)[None], cov[None])[0], np.degrees([0.01, 0.02, 0.03]))
    rng = np.random.default_rng(2)
    R = Rotation.from_euler("ZYX", [40, 25, -30], degrees=True).as_matrix()
    draws = euler_zyx_deg(R @ rotvec_to_matrix(rng.multivariate_normal(np.zeros(3), cov, 4000)))
    np.testing.assert_allclose(euler_sigmas_deg(R[None], cov[None])[0], draws.std(axis=0), rtol=0.06)
    assert euler_sigmas_deg(np.empty((0, 3, 3)), np.empty((0, 3, 3))).shape == (0, 3)
