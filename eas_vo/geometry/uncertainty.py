"""The uncertainty of absolute orientations: the chain's first-order propagation of its steps'
covariances, and sigmas per camera axis or per Euler angle for files and plots.

Convention (RelativeRotation.covariance's, which is GTSAM's): the covariance Sigma [rad^2]
(3, 3) of an orientation R_w_c is that of its right perturbation in the camera frame,
R_w_c,true = R_w_c Exp(delta), delta ~ N(0, Sigma); of a step R_i_j, in frame j.

The chain R_w_k = R_w_k-1 R_step (the paper's backend) moves frame k-1's error into frame k:
R_w_k-1 Exp(a) R_step Exp(b) = R_w_k Exp(R_step^T a) Exp(b), so to first order

    Sigma_k = R_step^T Sigma_k-1 R_step + Sigma_step,    Sigma_0 = 0

(frame 0 defines the world). A frame without a measured step keeps the previous rotation
(R_step = I), and the chain then misses whatever the camera turned meanwhile: its error grows
by that turn, which nothing measured. It is taken to be about as large as the turn of the
nearest measured step (constant angular velocity: the step ending at the frame before it, else
the first one after it), along any axis: Sigma_step = angle^2 I. A step whose estimator gives no
finite covariance (RelativeRotation.noise_covariance: infinite without inliers) is counted the
same way, its own turn the size of its error. Neither makes a sigma infinite: the chain's sigma
grows by a step's turn once and carries on from there. Without any measured step at all there
is no turn to go by: UNDETERMINED_VARIANCE per axis and frame (the gtsam backend's default
loose tie of such a frame, backend.gtsam.gap_sigma_rad)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from eas_vo.geometry.rotations import euler_zyx_deg, geodesic_angle, rotvec_to_matrix
from eas_vo.types import RelativeRotation

#: The variance [rad^2 per axis] of a frame's unmeasured turn when no step of the chain was
#: measured at all (a 1 rad sigma: nothing is known).
UNDETERMINED_VARIANCE = 1.0
#: The step of the central differences of the Euler angles' Jacobian [rad].
_EULER_STEP_RAD = 1e-6


def consecutive_steps(edges: Sequence[RelativeRotation]) -> dict[int, RelativeRotation]:
    """Frame k -> the edge k-1 -> k that the chain multiplies in (the last given, when a tracker
    gives several); skip edges (j != i + 1) are left out."""
    return {e.j: e for e in edges if e.j == e.i + 1}


def chain_covariance(n_frames: int, edges: Sequence[RelativeRotation]) -> np.ndarray:
    """The covariance [rad^2] (n_frames, 3, 3) of each frame's chained orientation R_w_ck
    (right perturbation, camera frame), propagated to first order along the consecutive edges
    (the module's docstring: frames without a step, steps without a finite covariance)."""
    steps = consecutive_steps(edges)
    out = np.zeros((n_frames, 3, 3))
    unmeasured = _unmeasured_variance(n_frames, steps)
    current = np.zeros((3, 3))
    for k in range(1, n_frames):
        edge = steps.get(k)
        R_step = np.eye(3) if edge is None else np.asarray(edge.R_i_j, float)
        step_cov = None if edge is None else _step_covariance(edge)
        if step_cov is None:
            step_cov = unmeasured[k] * np.eye(3)
        current = R_step.T @ current @ R_step + step_cov
        current = 0.5 * (current + current.T)
        out[k] = current
    return out


def _step_covariance(edge: RelativeRotation) -> np.ndarray | None:
    """The edge's covariance [rad^2] (3, 3) (RelativeRotation.noise_covariance), or None where
    its estimator gives none that is finite (no inliers)."""
    if edge.covariance is None and not np.isfinite(edge.sigma_rad):
        return None
    covariance = np.asarray(edge.noise_covariance(), float)
    return covariance if np.all(np.isfinite(covariance)) else None


def _unmeasured_variance(n_frames: int, steps: dict[int, RelativeRotation]) -> np.ndarray:
    """Per frame (n_frames,) [rad^2 per axis]: the squared turn of the frame's own step when it
    has one, else of the nearest measured step before it, else after it (UNDETERMINED_VARIANCE
    without any)."""
    measured = sorted(k for k in steps if 0 < k < n_frames)
    if not measured:
        return np.full(n_frames, UNDETERMINED_VARIANCE)
    turn = {k: float(geodesic_angle(np.eye(3), np.asarray(steps[k].R_i_j, float))) ** 2 for k in measured}
    out = np.empty(n_frames)
    last = turn[measured[0]]  # before the first measured step: the first one's turn
    for k in range(n_frames):
        last = turn.get(k, last)
        out[k] = last
    return out


def axis_sigmas(covariance: np.ndarray) -> np.ndarray:
    """The 1-sigma uncertainty [rad] about each camera axis x, y, z (..., 3) of covariances
    (..., 3, 3): the square roots of their diagonals."""
    return np.sqrt(np.clip(np.diagonal(np.asarray(covariance, float), axis1=-2, axis2=-1), 0.0, None))


def largest_sigma(covariance: np.ndarray) -> np.ndarray:
    """The 1-sigma uncertainty [rad] along the worst axis (...,) of covariances (..., 3, 3): the
    square root of the largest eigenvalue."""
    covariance = np.asarray(covariance, float)
    return np.sqrt(np.clip(np.linalg.eigvalsh(0.5 * (covariance + np.swapaxes(covariance, -1, -2)))[..., -1], 0, None))


def euler_sigmas_deg(R_w_c: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """The 1-sigma uncertainty [deg] (N, 3) of the roll, pitch and yaw (euler_zyx_deg) of
    orientations R_w_c (N, 3, 3) whose right perturbations in the camera frame have `covariance`
    (N, 3, 3) [rad^2]: sqrt(diag(J Sigma J^T)), J the angles' Jacobian in the perturbation (central
    differences). Unbounded near pitch +-90 deg, where roll and yaw are not defined; the result
    is independent of a world rotation applied to R_w_c on the left (an alignment) except through
    the Euler angles themselves."""
    R_w_c = np.asarray(R_w_c, float)
    n = len(R_w_c)
    if n == 0:
        return np.empty((0, 3))
    J = np.empty((n, 3, 3))
    for axis in range(3):
        h = np.zeros(3)
        h[axis] = _EULER_STEP_RAD
        plus = euler_zyx_deg(R_w_c @ rotvec_to_matrix(h))
        minus = euler_zyx_deg(R_w_c @ rotvec_to_matrix(-h))
        d = (plus - minus + 180.0) % 360.0 - 180.0  # across the +-180 deg cut
        J[:, :, axis] = d / (2 * _EULER_STEP_RAD)
    variance = np.einsum("nij,njk,nik->ni", J, np.asarray(covariance, float), J)
    return np.sqrt(np.clip(variance, 0.0, None))
