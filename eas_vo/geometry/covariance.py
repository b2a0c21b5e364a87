"""The covariance of a relative rotation measured from bearing correspondences.

Convention everywhere: a covariance Sigma [rad^2] (3, 3) of R_i_j (frame j to frame i) is that
of the right perturbation in frame j, the later view: R_i_j,true = R_i_j Exp(delta),
delta ~ N(0, Sigma). It is GTSAM's convention for a BetweenFactor's noise, so an edge's
covariance is its factor's noise model as it is.

Two estimates from the same linearisation about the measured model, both from the inliers only:

- `information`: the inverse of the Fisher information of the rotation given the inlier
  bearings and the image noise sigma estimated from their residuals (the per-axis noise of
  TwoViewRotation.residual): for the rotation-only model the 3x3 information
  sum_k (I - b_k b_k^T) / sigma^2 (b_k the rotated bearing: a rotation about b_k moves it not
  at all, which is why a narrow field of view measures the turn about its optical axis
  poorly); for the five-point model the Sampson residuals' 5x5 information in the rotation
  and the translation's direction, the translation marginalised out (its Schur complement):
  a turn the translation could also explain is measured no better than the two can be told
  apart; for a plane's homography R + u n^T the transfer residuals' 8x8 information in the
  rotation, u (the translation over the plane's distance) and the plane's normal, the last
  two marginalised out alike (the rotation-only information at the homography's rotation
  would take the plane's part as known: over 200 times too confident a NEES even at no
  translation).
- `bootstrap`: the spread of one Gauss-Newton step from the measured model on each of
  BOOTSTRAP_DRAWS resamples (with replacement) of the inliers and their residuals: no noise
  model, so it follows residuals that differ from point to point.

Both are then multiplied by SCALE, one factor per method and model family, fitted on real
tracking: the linearisation takes the inliers' errors as independent, and LK's are not.

`benchmarks/nees.py` measures both against ground truth (docs/uncertainty.md)."""

from __future__ import annotations

import numpy as np

from eas_vo.geometry.rotations import rotvec_to_matrix

#: The covariance methods (see the module's docstring).
METHODS = ("information", "bootstrap")
#: Resamples of the inliers the bootstrap draws (a fixed seed: the same data give the same
#: covariance). 200 draws put a variance within about 10 % (its relative standard error is
#: sqrt(2 / draws)).
BOOTSTRAP_DRAWS = 200
#: The factor a covariance is multiplied by, per (method, model family): `essential`, and
#: `rotation` for the rotation-only and homography models (homography edges, loops only, are
#: too few to have their own). The linearisation (exact on
#: synthetic pairs with independent pixel noise: tests/eas_vo/geometry/test_covariance.py)
#: takes the inliers' errors as independent; LK's tracks of one frame pair are not (they share
#: the images' blur, noise and frontend), so the error of a step shrinks far less with its
#: inliers than the linearisation says. Each factor brings the median NEES of the choice data
#: (klt with paper.toml and best.toml, every frontend, and match, on synthetic:default and the
#: real excerpt shapes_rotation's first 20 s; the reference's own noise added on the real
#: excerpt) to chi-square(3)'s median: benchmarks/nees.py, docs/uncertainty.md.
SCALE = {
    ("information", "essential"): 119.0,
    ("information", "rotation"): 256.0,
    ("bootstrap", "essential"): 105.0,
    ("bootstrap", "rotation"): 267.0,
}
#: The covariance of a rotation the data do not determine [rad^2 per axis]: a 1 rad sigma,
#: about which a backend weighing edges by their covariance all but ignores it.
UNDETERMINED_VARIANCE = 1.0
#: The smallest variance a covariance keeps along any axis [rad^2]: a microradian, so that
#: noise-free data still give a covariance a backend can invert.
MIN_VARIANCE = 1e-12
#: The step of the central differences of the Sampson residuals [rad, and unit-vector units of
#: the translation's direction].
_STEP = 1e-6


def skew(v: np.ndarray) -> np.ndarray:
    """The cross-product matrices [v]x (..., 3, 3) of vectors v (..., 3): [v]x w = v x w."""
    v = np.asarray(v, float)
    S = np.zeros(v.shape + (3,))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return S - np.swapaxes(S, -1, -2)


def rotation_only_covariance(
    R_cur_prev: np.ndarray, f_prev: np.ndarray, f_cur: np.ndarray, sigma: float, method: str = "information"
) -> np.ndarray:
    """The covariance [rad^2] of R_prev_cur (right perturbation, current frame) measured by the
    rotation-only model from inlier bearings f_prev, f_cur (N, 3) with per-axis noise `sigma`
    [rad ~ normalised image units]."""
    b = f_prev @ R_cur_prev.T
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    # moving R_cur_prev by Exp(e) on the left moves b by e x b = -[b]x e; R_prev_cur's right
    # perturbation in the current frame is then -e, whose covariance is the same
    J = -skew(b)
    residual = f_cur - b  # tangent to the sphere at b to first order
    scale = SCALE.get((method, "rotation"), 1.0)
    if method == "bootstrap":
        return _bootstrap(J, residual, scale=scale)
    information = np.einsum("nki,nkj->ij", J, J) / max(sigma, 1e-12) ** 2
    return _inverse(information / scale, len(b) >= 2)


def essential_covariance(
    E: np.ndarray,
    R_cur_prev: np.ndarray,
    x_prev: np.ndarray,
    x_cur: np.ndarray,
    sigma: float,
    method: str = "information",
) -> np.ndarray:
    """The covariance [rad^2] of R_prev_cur (right perturbation, current frame) measured by the
    five-point model E ~ [t]x R_cur_prev from inlier normalised points x_prev, x_cur (N, 2) with
    per-axis noise `sigma` [normalised units], the translation's direction marginalised out."""
    t = np.linalg.svd(E)[0][:, 2]  # E^T t = 0: the epipole of the current view
    basis = np.linalg.svd(np.eye(3) - np.outer(t, t))[0][:, :2]  # the tangent plane at t
    a = np.column_stack([x_prev, np.ones(len(x_prev))])
    b = np.column_stack([x_cur, np.ones(len(x_cur))])

    steps = np.vstack([_STEP * np.eye(5), -_STEP * np.eye(5), np.zeros((1, 5))])  # (11, 5), all at once
    directions = t + steps[:, 3:] @ basis.T
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    r = _signed_sampson(skew(directions) @ rotvec_to_matrix(steps[:, :3]) @ R_cur_prev, a, b)  # (11, N)
    J = ((r[:5] - r[5:10]) / (2 * _STEP)).T
    # (N, 5); the rotation's part is -1 times that of R_prev_cur's perturbation: same covariance
    return _rotation_marginal(J[:, None, :], r[10][:, None], sigma, method, "essential", 5)


def homography_covariance(
    H: np.ndarray,
    R_cur_prev: np.ndarray,
    x_prev: np.ndarray,
    x_cur: np.ndarray,
    sigma: float,
    method: str = "information",
) -> np.ndarray:
    """The covariance [rad^2] of R_prev_cur (right perturbation, current frame) measured by a
    plane's homography H ~ R_cur_prev + u n^T (the decomposition's rotation; u the translation
    over the plane's distance, n its unit normal in the previous frame) from inlier normalised
    points x_prev, x_cur (N, 2) with per-axis transfer noise `sigma` [normalised units], u and n
    marginalised out. Without translation n is undetermined; its directions then carry no
    information and the pseudo-inverse leaves them out."""
    Hs = H / np.linalg.svd(H, compute_uv=False)[1]  # the decomposition's scale: R + u n^T, up to sign
    plane = min((Hs - R_cur_prev, -Hs - R_cur_prev), key=lambda D: np.linalg.svd(D, compute_uv=False)[1])
    U, S, Vt = np.linalg.svd(plane)  # rank one: u n^T
    u0, n0 = S[0] * U[:, 0], Vt[0]
    basis = np.linalg.svd(np.eye(3) - np.outer(n0, n0))[0][:, :2]  # the tangent plane at n0
    a = np.column_stack([x_prev, np.ones(len(x_prev))])

    def residuals(p: np.ndarray) -> np.ndarray:
        n = n0 + basis @ p[6:]
        y = a @ (rotvec_to_matrix(p[:3]) @ R_cur_prev + np.outer(u0 + p[3:6], n / np.linalg.norm(n))).T
        return y[:, :2] / y[:, 2:] - x_cur  # (N, 2)

    J = np.stack(
        [(residuals(_STEP * e) - residuals(-_STEP * e)) / (2 * _STEP) for e in np.eye(8)], axis=-1
    )  # (N, 2, 8); the rotation's part is -1 times that of R_prev_cur's perturbation: same covariance
    return _rotation_marginal(J, residuals(np.zeros(8)), sigma, method, "rotation", 4)


def _rotation_marginal(
    J: np.ndarray, residual: np.ndarray, sigma: float, method: str, family: str, minimum: int
) -> np.ndarray:
    """The covariance [rad^2] of the first three parameters (the rotation) of a model whose
    residuals `residual` (N, m) have the Jacobian J (N, m, p) and per-axis noise `sigma`, the
    other parameters marginalised out (a pseudo-inverse: directions the data do not determine
    carry no information), times SCALE[(method, family)]; undetermined below `minimum` points."""
    scale = SCALE.get((method, family), 1.0)
    if method == "bootstrap":
        return _bootstrap(J, residual, keep=3, scale=scale)
    information = np.einsum("nki,nkj->ij", J, J) / max(sigma, 1e-12) ** 2 / scale
    if len(J) < minimum:
        return _inverse(information[:3, :3], False)
    rr, rt, tt = information[:3, :3], information[:3, 3:], information[3:, 3:]
    return _inverse(rr - rt @ np.linalg.pinv(tt, hermitian=True) @ rt.T, True)


def _signed_sampson(E: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The Sampson distance of b^T E a = 0 with its sign (homogeneous points a, b (N, 3)), for
    each essential matrix of E (..., 3, 3): (..., N)."""
    Ea, Etb = a @ np.swapaxes(E, -1, -2), b @ E
    den = np.sqrt(Ea[..., 0] ** 2 + Ea[..., 1] ** 2 + Etb[..., 0] ** 2 + Etb[..., 1] ** 2)
    return np.sum(b * Ea, axis=-1) / np.maximum(den, 1e-300)


def _bootstrap(J: np.ndarray, residual: np.ndarray, keep: int = 3, scale: float = 1.0) -> np.ndarray:
    """The covariance of the first `keep` parameters of one Gauss-Newton step solve(J^T J, J^T r)
    over BOOTSTRAP_DRAWS resamples of the points (J (N, m, p), r (N, m)), times `scale`;
    undetermined where fewer points than parameters, or a resample's normal equations are
    singular."""
    n, p = J.shape[0], J.shape[2]
    if n < max(p, 2):
        return _inverse(np.zeros((3, 3)), False)
    draws = np.random.default_rng(0).integers(0, n, (BOOTSTRAP_DRAWS, n))
    JtJ = np.einsum("nki,nkj->nij", J, J)
    Jtr = np.einsum("nki,nk->ni", J, residual)
    normal = np.add.reduceat(JtJ[draws.ravel()], np.arange(0, draws.size, n))
    rhs = np.add.reduceat(Jtr[draws.ravel()], np.arange(0, draws.size, n))
    try:
        steps = np.linalg.solve(normal, rhs[..., None])[..., 0][:, :keep]
    except np.linalg.LinAlgError:
        return _inverse(np.zeros((3, 3)), False)
    return _capped(scale * np.cov(steps, rowvar=False))


def _inverse(information: np.ndarray, determined: bool) -> np.ndarray:
    """The covariance of an information matrix (3, 3); UNDETERMINED_VARIANCE where it is not
    determined (too few points, a singular or non-finite information)."""
    if determined and np.all(np.isfinite(information)):
        w, V = np.linalg.eigh(0.5 * (information + information.T))
        if w.min() > 0:
            return _capped((V / w) @ V.T)
    return UNDETERMINED_VARIANCE * np.eye(3)


def _capped(covariance: np.ndarray) -> np.ndarray:
    """`covariance` (symmetric) with every variance along its axes between MIN_VARIANCE and
    UNDETERMINED_VARIANCE."""
    w, V = np.linalg.eigh(0.5 * (covariance + covariance.T))
    if not np.all(np.isfinite(w)):
        return UNDETERMINED_VARIANCE * np.eye(3)
    return (V * np.clip(w, MIN_VARIANCE, UNDETERMINED_VARIANCE)) @ V.T
