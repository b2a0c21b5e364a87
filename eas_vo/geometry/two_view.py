"""Relative rotation from bearing correspondences: a rotation-only solver (2-point RANSAC,
then least squares), the five-point essential matrix, GRIC to choose between them, and a
plane's homography.

Conventions: `f_prev`, `f_cur` are (N, 3) unit bearings; the models map previous-frame
bearings into the current frame: f_cur ~ R_cur_prev f_prev (+ translation for E).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numba
import numpy as np

from eas_vo.geometry.covariance import essential_covariance, homography_covariance, rotation_only_covariance
from eas_vo.geometry.rotations import geodesic_angle


def bearings(pts_n: np.ndarray) -> np.ndarray:
    """Normalised image coordinates (N, 2) -> unit bearing vectors (N, 3)."""
    f = np.column_stack([pts_n, np.ones(len(pts_n))])
    return f / np.linalg.norm(f, axis=1, keepdims=True)


def kabsch(a: np.ndarray, b: np.ndarray, weights=None) -> np.ndarray:
    """The rotation R minimising sum w |b_i - R a_i|^2 (Wahba's problem); works on stacks
    (..., N, 3) -> (..., 3, 3)."""
    if weights is not None:
        a = a * weights[..., None]
    H = np.swapaxes(a, -1, -2) @ b
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros(H.shape)
    D[..., 0, 0] = D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    return np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)


def angular_residuals(R_cur_prev: np.ndarray, f_prev: np.ndarray, f_cur: np.ndarray) -> np.ndarray:
    """Angle [rad] between R f_prev and f_cur; stacks of R give (K, N)."""
    rotated = f_prev @ np.swapaxes(R_cur_prev, -1, -2)
    cos = np.clip(np.sum(rotated * f_cur, axis=-1), -1.0, 1.0)
    return np.arccos(cos)


def rotation_ransac(
    f_prev: np.ndarray,
    f_cur: np.ndarray,
    threshold_rad: float,
    confidence: float = 0.999,
    max_hypotheses: int = 256,
    batch: int = 32,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Pure-rotation model: 2-point minimal sets scored in batches until, given the best inlier
    ratio w so far, another sample is unlikely to do better (log(1 - confidence) / log(1 - w^2)
    samples, at most `max_hypotheses`), then least squares on the inliers (twice). Returns
    (R_cur_prev, inlier mask), or None with fewer than 2 points or when no sample is supported
    by two points (as with non-finite bearings, whose rotation would be NaN)."""
    n = len(f_prev)
    if n < 2:
        return None
    pairs = np.random.default_rng(seed).integers(0, n, (-(-max_hypotheses // batch) * batch, 2))
    cos_threshold = np.cos(threshold_rad)  # an angle below the threshold is a cosine above its cosine
    R_best, best_count, _ = _best_two_point_rotation(f_prev, f_cur, pairs, cos_threshold, confidence, batch)
    if best_count < 2:
        return None
    mask = np.einsum("ij,nj,ni->n", R_best, f_prev, f_cur) > cos_threshold
    for _ in range(2):
        if mask.sum() < 2:
            break
        R_best = kabsch(f_prev[mask], f_cur[mask])
        mask = angular_residuals(R_best, f_prev, f_cur) < threshold_rad
    return R_best, mask


@numba.njit(cache=True, nogil=True)
def _best_two_point_rotation(f_prev, f_cur, pairs, cos_threshold, confidence, batch):
    """The RANSAC loop of rotation_ransac over the drawn `pairs` (M, 2), a batch at a time
    (pairs of one point twice are skipped): the rotation with the most inliers, their
    number (-1 if no pair defined a rotation) and how many samples were drawn."""
    n = f_prev.shape[0]
    drawn, needed, best_count = 0, pairs.shape[0], -1
    R_best = np.eye(3)
    while drawn < needed:
        chosen = pairs[drawn : drawn + batch]
        drawn += batch
        chosen = chosen[chosen[:, 0] != chosen[:, 1]]
        if chosen.shape[0] == 0:
            continue
        R, counts = _two_point_hypotheses(f_prev, f_cur, chosen, cos_threshold)
        best = np.argmax(counts)
        if counts[best] > best_count:
            best_count, R_best = counts[best], R[best].copy()
            needed = min(pairs.shape[0], _samples_needed(best_count / n, confidence))
    return R_best, best_count, drawn


@numba.njit(cache=True, nogil=True)
def _pair_frame(v, i, j, F):
    """Write into F the orthonormal frame (columns: sum, difference, their cross product) of the
    unit vectors v[i], v[j]; False if they are (anti)parallel."""
    ns = nd = 0.0
    for r in range(3):
        F[r, 0] = v[i, r] + v[j, r]
        F[r, 1] = v[i, r] - v[j, r]
        ns += F[r, 0] * F[r, 0]
        nd += F[r, 1] * F[r, 1]
    if ns < 1e-24 or nd < 1e-24:
        return False
    ns, nd = np.sqrt(ns), np.sqrt(nd)
    for r in range(3):
        F[r, 0] /= ns
        F[r, 1] /= nd
    F[0, 2] = F[1, 0] * F[2, 1] - F[2, 0] * F[1, 1]
    F[1, 2] = F[2, 0] * F[0, 1] - F[0, 0] * F[2, 1]
    F[2, 2] = F[0, 0] * F[1, 1] - F[1, 0] * F[0, 1]
    return True


@numba.njit(cache=True, nogil=True)
def _two_point_hypotheses(f_prev, f_cur, pairs, cos_threshold):
    """For each 2-point sample (K, 2) of bearings: Kabsch's rotation of the pair in closed form
    (a1 + a2 and a1 - a2 are orthogonal, so a1 b1^T + a2 b2^T is already an SVD in the frames
    sum, difference, cross product of a and of b: R maps a's frame onto b's) and the number of
    points it maps within the threshold. Returns (K, 3, 3) rotations and (K,) counts (0 for an
    (anti)parallel pair, which defines no rotation)."""
    K, n = pairs.shape[0], f_prev.shape[0]
    R = np.zeros((K, 3, 3))
    counts = np.zeros(K, np.int64)
    A = np.empty((3, 3))
    B = np.empty((3, 3))
    for k in range(K):
        if not (_pair_frame(f_prev, pairs[k, 0], pairs[k, 1], A) and _pair_frame(f_cur, pairs[k, 0], pairs[k, 1], B)):
            continue
        for r in range(3):
            for c in range(3):
                R[k, r, c] = B[r, 0] * A[c, 0] + B[r, 1] * A[c, 1] + B[r, 2] * A[c, 2]
        count = 0
        for m in range(n):
            dot = 0.0
            for r in range(3):
                dot += f_cur[m, r] * (R[k, r, 0] * f_prev[m, 0] + R[k, r, 1] * f_prev[m, 1] + R[k, r, 2] * f_prev[m, 2])
            if dot > cos_threshold:
                count += 1
        counts[k] = count
    return R, counts


@numba.njit(cache=True, nogil=True)
def _samples_needed(inlier_ratio, confidence):
    """2-point samples needed to draw one all-inlier sample with probability `confidence`."""
    all_inliers = inlier_ratio**2
    if confidence >= 1.0 and all_inliers < 1.0:
        return 2**31 - 1
    if all_inliers >= 1.0:
        return 1
    if all_inliers <= 0.0:
        return 2**31 - 1
    return int(np.ceil(np.log(1.0 - confidence) / np.log(1.0 - all_inliers)))


def sampson_residuals(E: np.ndarray, x_prev: np.ndarray, x_cur: np.ndarray) -> np.ndarray:
    """First-order geometric error of x_cur^T E x_prev = 0 (normalised image units)."""
    a = np.column_stack([x_prev, np.ones(len(x_prev))])
    b = np.column_stack([x_cur, np.ones(len(x_cur))])
    Ea = a @ E.T
    Etb = b @ E
    num = np.sum(b * Ea, axis=1) ** 2
    den = Ea[:, 0] ** 2 + Ea[:, 1] ** 2 + Etb[:, 0] ** 2 + Etb[:, 1] ** 2
    return np.sqrt(num / np.maximum(den, 1e-300))


def gric(residuals: np.ndarray, sigma: float, model_dim: int, params: int, data_dim: int = 4) -> float:
    """Torr's Geometric Robust Information Criterion (lower is better).

    rho(e) = min(e^2 / sigma^2, 2 (r - d)); GRIC = sum rho + log(r) d n + log(r n) k,
    with r the data dimension (4: two image points), d the model manifold dimension
    (2 for a rotation, 3 for an essential matrix) and k its parameters (3, 5).
    """
    n = len(residuals)
    rho = np.minimum((residuals / sigma) ** 2, 2.0 * (data_dim - model_dim))
    return float(rho.sum() + np.log(data_dim) * model_dim * n + np.log(data_dim * n) * params)


def essential_rotation(
    x_prev: np.ndarray, x_cur: np.ndarray, threshold: float, confidence: float, method: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Five-point essential matrix and its rotation: (E, R_cur_prev, inlier mask) or None.

    E's decomposition gives two rotations, R and its twist (R followed by a half turn about
    the baseline); the one whose rotated bearings lie closer to the current ones over the
    inliers (median angle, twist_free) is taken. Unlike cheirality (which views the
    triangulated points lie in front of), this stays decided as the baseline vanishes: with no
    translation every point is at infinity, cheirality is a coin toss, and a camera that did
    not move came out turned by a half turn.
    """
    E, mask = cv2.findEssentialMat(x_prev, x_cur, np.eye(3), method=method, prob=confidence, threshold=threshold)
    if E is None or E.shape[0] < 3 or mask is None:
        return None
    E = E[:3]
    mask = mask.ravel().astype(bool)
    if not mask.any():
        return None
    R1, R2, _ = cv2.decomposeEssentialMat(E)
    return E, twist_free(R1, R2, bearings(x_prev[mask]), bearings(x_cur[mask])), mask


def twist_free(R1: np.ndarray, R2: np.ndarray, f_prev: np.ndarray, f_cur: np.ndarray) -> np.ndarray:
    """Of an essential matrix's two rotations R1, R2 (R_cur_prev, one the other's twist about
    the baseline t), the one with the smaller median angular residual on the bearings.

    Why it is the true one: in the epipolar plane of a point, with angles measured from t, let
    the true rotation put the previous bearing at alpha and the current bearing be at beta.
    The point lies in front of the previous camera, so beta is on the same side of t as alpha
    (0 < alpha, beta < pi, up to a common sign); the twist puts the bearing at -alpha. Then
    |beta - alpha| < min(beta + alpha, 2 pi - beta - alpha): every point in front of the
    first camera is closer to the true rotation's bearing, whatever the baseline's length.
    """
    residuals = [np.median(angular_residuals(R, f_prev, f_cur)) for R in (R1, R2)]
    return R1 if residuals[0] <= residuals[1] else R2


#: A homography's decomposition is taken to put the points in front of both views when this
#: share of its inliers is: noise puts a few points of a steeply tilted plane, near its
#: horizon, behind it, and an all-or-nothing test would then keep only the dual.
IN_FRONT_SHARE = 0.9


def homography_rotation(
    x_prev: np.ndarray, x_cur: np.ndarray, threshold: float, confidence: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The rotation of a plane's homography H ~ R + t n^T / d: (R_cur_prev, inlier mask,
    transfer residuals [normalised units], H), or None where H determines none: fewer than 4
    points, no homography, no decomposition putting the inliers in front of both views, or
    two that do and differ by more than `threshold` [normalised units ~ rad].

    H holds exactly for the points of a plane seen from two places, and for a pure rotation
    (H = R), so the camera's translation is kept out of R where a rotation-only model would
    turn its parallax into rotation. A point x of the first view and its match x' lie in front
    of a decomposition's plane (normal n in the first view's frame) when n . x > 0 and
    (R n) . x' > 0 (homogeneous normalised coordinates). Up to two decompositions pass with a
    translation: the true one and its dual, whose normal lies along the translation, which
    nothing in two views tells apart; without one (t ~ 0, the normal undetermined) any
    number, with nearly the same rotation.
    """
    if len(x_prev) < 4:
        return None
    H, mask = cv2.findHomography(x_prev, x_cur, cv2.RANSAC, threshold, confidence=confidence)
    if H is None or mask is None or not mask.any():
        return None
    mask = mask.ravel().astype(bool)
    _, rotations, _, normals = cv2.decomposeHomographyMat(H, np.eye(3))
    x = np.column_stack([x_prev[mask], np.ones(mask.sum())])
    x_next = np.column_stack([x_cur[mask], np.ones(mask.sum())])
    in_front = [  # (exact data can decompose into NaN: no point is in front of those)
        R
        for R, n in zip(rotations, normals)
        if np.mean((x @ n.ravel() > 0) & (x_next @ (R @ n).ravel() > 0)) >= IN_FRONT_SHARE
    ]
    if not in_front or any(geodesic_angle(in_front[0], R) > threshold for R in in_front[1:]):
        return None
    transferred = cv2.perspectiveTransform(np.asarray(x_prev, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)
    return in_front[0], mask, np.linalg.norm(transferred - x_cur, axis=1), H


#: Robust estimators around the five-point solver, by config name.
ESSENTIAL_METHODS = {
    "usac": cv2.USAC_DEFAULT,
    "ransac": cv2.RANSAC,
    "magsac": cv2.USAC_MAGSAC,
    "lmeds": cv2.LMEDS,
}

#: How the rotation of a frame pair is measured (see rotation_from_correspondences).
GEOMETRIES = ("essential", "rotation", "auto", "homography")


class TwoViewRotation(NamedTuple):
    """A relative rotation measured from correspondences."""

    R_prev_cur: np.ndarray  #: maps current-frame vectors into the previous frame
    inliers: int  #: correspondences the model explains
    model: str  #: `essential`, `rotation` or `homography`
    residual: float  #: robust per-axis noise of the inliers [normalised image units ~ rad], see _noise
    covariance: np.ndarray  #: of R_prev_cur [rad^2] (3, 3): geometry.covariance's convention and methods
    inlier_mask: np.ndarray  #: (N,) bool: which of the correspondences the model explains


def rotation_from_correspondences(
    pts_prev_n: np.ndarray,
    pts_cur_n: np.ndarray,
    threshold: float,
    confidence: float,
    method: str = "usac",
    geometry: str = "essential",
    covariance: str = "information",
) -> TwoViewRotation | None:
    """The relative rotation of two views from matched normalised image points.

    Args:
        pts_prev_n, pts_cur_n: (N, 2) matching normalised image coordinates.
        threshold: inlier threshold in normalised units (pixels / focal length).
        confidence: robust estimator confidence.
        method: a key of ESSENTIAL_METHODS (the five-point estimator's robust loop).
        geometry: `essential` (the paper: five-point essential matrix), `rotation`
            (rotation-only: 2-point RANSAC and least squares on bearings), `auto` (both, the
            better by GRIC), or `homography` (a plane's homography and its rotation where it
            determines one, see homography_rotation; else rotation-only). Whatever the
            geometry, views that show no motion (`motionless`) are measured rotation-only:
            no parallax determines no essential matrix, and a still camera is no turn.
            `auto` and `homography`, which choose a model, take the rotation-only one where
            the other's rotation does not explain its inliers (`explains`); `essential`, the
            paper's, keeps its rotation (the trackers judge a doubtful one,
            measurement.measure).
        covariance: how the rotation's covariance is estimated (geometry.covariance.METHODS).

    Returns:
        The rotation, its inlier count, the model used, the inliers' per-axis noise (sigma
        from their median residual, see _noise) and the rotation's covariance, or
        None when no model is found: for `essential`, when the five-point solver finds none
        (or, where rotation-only measures, its RANSAC); for the others, when the
        rotation-only RANSAC finds none.
    """
    f_prev, f_cur = bearings(pts_prev_n), bearings(pts_cur_n)
    still = motionless(f_prev, f_cur, threshold)

    def essential_result(E: np.ndarray, R: np.ndarray, mask: np.ndarray, residuals: np.ndarray) -> TwoViewRotation:
        sigma = _noise(residuals[mask], dims=1)
        cov = essential_covariance(E, R, pts_prev_n[mask], pts_cur_n[mask], sigma, covariance)
        return TwoViewRotation(R.T, int(mask.sum()), "essential", sigma, cov, mask)

    def bearing_result(R: np.ndarray, mask: np.ndarray, model: str, residuals: np.ndarray) -> TwoViewRotation:
        sigma = _noise(residuals[mask], dims=2)
        cov = rotation_only_covariance(R, f_prev[mask], f_cur[mask], sigma, covariance)
        return TwoViewRotation(R.T, int(mask.sum()), model, sigma, cov, mask)

    if geometry == "essential" and not still:
        found = essential_rotation(pts_prev_n, pts_cur_n, threshold, confidence, ESSENTIAL_METHODS[method])
        if found is None:
            return None
        E, R_ess, ess_mask = found
        return essential_result(E, R_ess, ess_mask, sampson_residuals(E, pts_prev_n, pts_cur_n))
    rotation = rotation_ransac(f_prev, f_cur, threshold, confidence)
    if rotation is None:
        return None
    R_rot, rot_mask = rotation
    rot_residuals = angular_residuals(R_rot, f_prev, f_cur)
    if geometry == "rotation" or still:
        return bearing_result(R_rot, rot_mask, "rotation", rot_residuals)
    if geometry == "homography":
        found = homography_rotation(pts_prev_n, pts_cur_n, threshold, confidence)
        if found is None or not explains(found[0], f_prev[found[1]], f_cur[found[1]], threshold):
            return bearing_result(R_rot, rot_mask, "rotation", rot_residuals)
        R_hom, hom_mask, hom_residuals, H = found
        sigma = _noise(hom_residuals[hom_mask], dims=2)
        cov = homography_covariance(H, R_hom, pts_prev_n[hom_mask], pts_cur_n[hom_mask], sigma, covariance)
        return TwoViewRotation(R_hom.T, int(hom_mask.sum()), "homography", sigma, cov, hom_mask)
    found = essential_rotation(pts_prev_n, pts_cur_n, threshold, confidence, ESSENTIAL_METHODS[method])
    if found is None or not explains(found[1], f_prev[found[2]], f_cur[found[2]], threshold):
        return bearing_result(R_rot, rot_mask, "rotation", rot_residuals)
    E, R_ess, ess_mask = found
    sigma = threshold / 2.0
    ess_residuals = sampson_residuals(E, pts_prev_n, pts_cur_n)
    gric_rot = gric(rot_residuals, sigma, model_dim=2, params=3)
    gric_ess = gric(ess_residuals, sigma, model_dim=3, params=5)
    if gric_rot <= gric_ess:
        return bearing_result(R_rot, rot_mask, "rotation", rot_residuals)
    return essential_result(E, R_ess, ess_mask, ess_residuals)


def motionless(f_prev: np.ndarray, f_cur: np.ndarray, threshold_rad: float) -> bool:
    """Whether the views show no motion: at least half of the bearings moved less than the
    inlier threshold [rad]. The identity then explains them as well as any model does, and the
    five-point solver has no parallax to measure: a point that stays put lies on the epipolar
    line of every translation, so E is undetermined (any skew-symmetric matrix fits, whose
    decomposition is the identity and a half turn)."""
    return bool(np.median(angular_residuals(np.eye(3), f_prev, f_cur)) < threshold_rad)


#: How many times as far as the bearings moved a rotation may leave them from where they are
#: seen (its parallax) and still be what they show: a right rotation leaves the parallax p of
#: the camera's translation, and the bearings moved by p + r (r the rotation's own flow), so
#: it fails only where r cancels more than half of p, a camera turning to follow what it
#: passes: its images then move less than half of what the translation alone would make
#: them, and over one view pair a narrow field of view barely tells such a turn from a
#: sideways move (the rotation-translation ambiguity: Adiv, "Inherent ambiguities in
#: recovering 3-D motion and structure from a noisy flow field", IEEE PAMI 11(5), 1989).
PARALLAX_PER_MOTION = 2.0


def explains(R_cur_prev: np.ndarray, f_prev: np.ndarray, f_cur: np.ndarray, threshold_rad: float) -> bool:
    """Whether the rotation leaves the previous bearings, turned, no further from the current
    ones than PARALLAX_PER_MOTION times they moved, plus the inlier threshold [rad] (median
    angles): the check of a rotation against the correspondences it claims to explain. One
    that fails turns the bearings far further than they moved, as the rotation of an
    essential matrix fitted to chance inliers, or to flow too small to tell rotation from
    translation, does; one that passes turns them by at most about three times their median
    motion (the triangle inequality)."""
    if len(f_prev) == 0:
        return False
    moved = np.median(angular_residuals(np.eye(3), f_prev, f_cur))
    return bool(np.median(angular_residuals(R_cur_prev, f_prev, f_cur)) <= PARALLAX_PER_MOTION * moved + threshold_rad)


#: Median of |x| for x ~ N(0, 1) in 1 and of ||x|| in 2 dimensions (half-normal, Rayleigh).
_MEDIAN_NORM = {1: 0.6745, 2: 1.1774}


def _noise(inlier_residuals: np.ndarray, dims: int) -> float:
    """The inliers' robust per-axis noise: sigma = their median residual over the median of a
    standard `dims`-dimensional Gaussian's norm, so that the angular residual of the rotation
    model (a 2-D distance) and the Sampson distance (1-D, to the epipolar line) are on one
    scale (0 without inliers)."""
    return float(np.median(inlier_residuals)) / _MEDIAN_NORM[dims] if len(inlier_residuals) else 0.0
