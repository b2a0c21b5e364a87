"""How the gyro is turned and clocked against the images: the rotation that maps the tracked
frame-to-frame rotations onto the gyro's, and the clock shift that explains them best."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, matrix_to_rotvec
from eas_vo.imu.thresholds import MIN_AGREEMENT_PAIRS, MIN_TURN_RAD
from eas_vo.types import ImuSeries


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


#: How far around its last estimate the IMU's clock is searched [s], in 1 ms steps (about a
#: DAVIS frame interval), and how many times the fit and the search are redone at the new
#: estimate (the pairs that agree depend on the clock: a large error is under-read the first time).
CLOCK_SEARCH_S = 0.05


CLOCK_ROUNDS = 4


#: The gyro's rates negated are fitted only when its own fit is turned this much [deg] or more.
MIRROR_TRIED_DEG = 10.0


def imu_agreement(t: np.ndarray, edges, imu: ImuSeries) -> ImuAgreement | None:
    """Compare the rotation vectors of the consecutive edges (camera frame) with the gyro's
    over the same frame times [s] (`imu` in the camera frame, on the frames' clock): the
    rotation between them (_fit_axes) and the gyro's clock (_best_clock_shift), redone at the
    new clock until it moves less than 1 ms. None without MIN_AGREEMENT_PAIRS pairs to compare. The gyro's rates
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
        if keep.sum() < MIN_AGREEMENT_PAIRS:
            break
        v, g = v_all[keep], g[keep]
        R, agree = _fit_axes(v, g)
        if agree.sum() < MIN_AGREEMENT_PAIRS:
            break
        best, limit, residual, unshifted = _best_clock_shift(
            t0[keep][agree], t1[keep][agree], v[agree] @ R.T, turned, imu, shift
        )
        singular = np.linalg.svd(v[agree], compute_uv=False)
        spread = float(singular[1] / max(singular[0], 1e-12))
        moved, shift = abs(best - shift), best
        found = ImuAgreement(
            R,
            len(v),
            int(agree.sum()),
            spread,
            best,
            limit,
            residual,
            unshifted,
            _fit_sigma_deg(v[agree] @ R.T, g[agree]),
        )
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


def _best_clock_shift(
    t0: np.ndarray, t1: np.ndarray, expected: np.ndarray, turned, imu: ImuSeries, around: float
) -> tuple[float, bool, float, float]:
    """The shift d [s] of the gyro's clock (read at t + d) whose rotation vectors over frame
    times t0 < t1 (`turned`: ImuSeries.turned_since_start) best match `expected` (N, 3) [rad], by the median
    distance on a 1 ms grid within CLOCK_SEARCH_S of `around`, refined by a parabola. Returns
    d, whether it lies on the grid's edge, the median at d and the median at 0 (pairs the
    gyro covers at every shift only)."""
    span = CLOCK_SEARCH_S + abs(around)
    covered = (t0 - span >= imu.t[0]) & (t1 + span <= imu.t[-1])
    t0, t1, expected = t0[covered], t1[covered], expected[covered]
    if len(t0) < MIN_AGREEMENT_PAIRS:
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
