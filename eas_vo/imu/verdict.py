"""Whether the images agree with the gyro, after tracking (judge_gyro): the confidently measured
frame-to-frame rotations against the gyro's over the same intervals, as configured.

The readings are taken in the camera frame on the frames' clock (ImuSeries.in_camera_frame).
What only the images can show (axes, sign, scale or clock wrong) is judged from the
confidently measured frame-to-frame rotations: a gyro they contradict is not used. Where the
gyro reads no rotation beyond its noise and an estimator's rotation (with its own sigma) turns
beyond both noises, the scene moved, not the camera (still_gyro_pairs): such pairs judge nothing."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, gyro_rotation, matrix_to_rotvec, rotvec_to_matrix
from eas_vo.imu.thresholds import MIN_TURN_RAD
from eas_vo.types import ImuSeries, RelativeRotation

#: A frame-to-frame rotation with this many inliers is a confident measurement of the images
#: (the 2-point rotation model's RANSAC: 30 inliers leave well under one chance in a million
#: that an outlier model explains them).
CONFIDENT_INLIERS = 30


#: The gyro disagrees with a pair when the angle between the two rotations exceeds this part of
#: the larger of them: a gyro read in the wrong unit or not at all gives 1 or more, a sign flip 2,
#: an axis swap 1.4, a clock a frame interval off about 1 at constant motion; a right one stays
#: well below (docs/imu.md, "How the check's thresholds were chosen").
DISAGREEMENT = 0.5


#: The images can judge the gyro from this many confident pairs that turned.
MIN_JUDGED_PAIRS = 10


#: A gyro turning this much more or less than the images (its fitted scale off 1 by more, and
#: by more than FIT_SIGMAS of the fit's standard error) is wrong: a MEMS gyro's sensitivity is
#: within 3 % of its datasheet's (docs/imu.md has what right gyros fit).
MAX_SCALE_ERROR = 0.2


#: A gyro reading this much [rad/s] more than the images turn, constantly (its fitted bias's
#: norm, and beyond FIT_SIGMAS of the fit's standard error), has a bias the pose graph's prior
#: cannot absorb (backend.gyro_bias_sigma: 0.01); above the bias the images' own systematic error
#: looks like on right gyros, which cannot be told from a gyro's (docs/imu.md).
MAX_BIAS_RAD_S = 0.15


FIT_SIGMAS = 4.0


#: The scale and bias fits refute the gyro only over judged pairs spanning this long [s]: the
#: images' systematic errors (the events' latency at one speed, one texture in view) last as long
#: as the motion that causes them, and the fits' standard errors, taking the pairs for
#: independent, understate them over a short stretch (docs/imu.md); hand-held motion changes
#: speed and axis within about a second. Most pairs disagreeing refutes it over any span: a
#: wrong sign, axis or clock shows in every pair.
MIN_FIT_SPAN_S = 1.0


#: A gyro read in deg/s as rad/s (or the reverse) turns this many times as far as the images.
DEG_PER_RAD = float(np.degrees(1.0))


#: The gyro's white-noise density [rad/s/sqrt(Hz)] and the sigma of the constant bias it may keep
#: [rad/s], for an IMU whose own calibration is not given: the MPU-6150-like DAVIS IMU the
#: simulator models (datasets.simulator ImuModel) and the gtsam backend assumes (backend.gyro_noise,
#: backend.gyro_bias_sigma). Over an interval dt the integrated rotation's per-axis sigma is then
#: sqrt(GYRO_NOISE_DENSITY^2 dt + (GYRO_BIAS_RAD_S dt)^2): the white noise's angle random walk and
#: the bias times the interval.
GYRO_NOISE_DENSITY = 0.003


GYRO_BIAS_RAD_S = 0.01


#: The 0.999 quantile of the chi-square distribution with 3 degrees of freedom
#: (scipy.stats.chi2.ppf(0.999, 3)): a 3-vector of independent unit Gaussians is this long
#: squared once in a thousand draws.
CHI2_3_999 = 16.266


@dataclass(frozen=True)
class GyroVerdict:
    """What the images say of the gyro.

    Attributes:
        judged: confident frame-to-frame rotations (CONFIDENT_INLIERS) over intervals the gyro
            measures, where either turned at least MIN_TURN_RAD, less the `still` ones.
        disagreeing: those whose angle to the gyro's exceeds DISAGREEMENT of the larger rotation.
        median_off_deg: the median angle [deg] between the two rotations over the judged pairs.
        scale, scale_se: the gyro's rotation vectors over the judged pairs fitted as scale times
            the images' plus a constant bias times the interval (least squares), and its
            standard error.
        bias_rad_s, bias_se_rad_s: that bias's norm [rad/s] and its standard error.
        judged_span_s: from the start of the first judged pair to the end of the last [s].
        rescaled_disagreeing: the judged pairs that still disagree (DISAGREEMENT) with the
            images' rotation vectors multiplied by `scale`.
        still: (frame j, angle [rad] between the two rotations) of each consecutive pair (j - 1,
            j) over which the edge turns while the gyro reads still (still_gyro_pairs), of the
            `compared` pairs with an estimator's own sigma that the gyro measures.
    """

    judged: int
    disagreeing: int
    median_off_deg: float
    scale: float = 1.0
    scale_se: float = 0.0
    bias_rad_s: float = 0.0
    bias_se_rad_s: float = 0.0
    judged_span_s: float = 0.0
    rescaled_disagreeing: int = 0
    still: tuple[tuple[int, float], ...] = ()
    compared: int = 0

    @property
    def scale_off(self) -> bool:
        off = abs(self.scale - 1.0)
        return off > MAX_SCALE_ERROR and off > FIT_SIGMAS * self.scale_se

    @property
    def scaled_alike(self) -> bool:
        """The gyro and the images turn about the same axes, one scale apart (scale_off, and once
        the images' rotations are scaled by it most judged pairs agree), by no factor a unit
        explains (deg/s for rad/s, within 10 %). The images' rotations scale with 1 / focal_px
        (an image shift of d px is read as d / focal_px rad), while a MEMS gyro's sensitivity
        is within 3 % of its datasheet's: this points first at the camera's focal length (a
        calibration of another resolution or binning: a factor of 2), then at a gyro read with
        the wrong full-scale setting, not at its axes, signs or clock. The rates alone cannot
        tell the two apart (a focal length off scales cmax's roll too, as the gyro's scale
        would; docs/imu.md, "A gyro that cannot be right is not used"), so the gyro is not
        fused with images it is one scale apart from (contradicts), and the warning names the
        camera first."""
        if not (self.scale_off and self.scale > 0 and self.rescaled_disagreeing <= self.judged / 2):
            return False
        return min(abs(np.log(self.scale * f)) for f in (DEG_PER_RAD, 1 / DEG_PER_RAD)) > np.log(1.1)

    @property
    def bias_off(self) -> bool:
        return self.bias_rad_s > MAX_BIAS_RAD_S and self.bias_rad_s > FIT_SIGMAS * self.bias_se_rad_s

    @property
    def can_tell(self) -> bool:
        return self.judged >= MIN_JUDGED_PAIRS

    @property
    def fit_off(self) -> bool:
        """The scale or bias fit is off (whether or not the pairs span enough to refute the gyro)."""
        return self.can_tell and (self.scale_off or self.bias_off)

    @property
    def contradicts(self) -> bool:
        """The images contradict the gyro: most judged pairs disagree (unless the two are one scale
        apart, scaled_alike: then the scale decides), or over MIN_FIT_SPAN_S or more its scale
        or bias is off."""
        if not self.can_tell:
            return False
        if self.disagreeing > self.judged / 2 and not self.scaled_alike:
            return True
        return self.fit_off and self.judged_span_s >= MIN_FIT_SPAN_S

    @property
    def use(self) -> str:
        """metrics.json's `gyro`: "used", "used unchecked" (the images cannot tell) or "not used"
        (they contradict it)."""
        if self.contradicts:
            return "not used"
        return "used" if self.can_tell else "used unchecked"

    def warnings(self, retracked: bool, findings: list[str]) -> list[str]:
        """The run's warnings on the gyro: one line when it is not used (`retracked`: the frames
        were tracked again without it) or used without the images' check, joined with the first
        of the `findings` of the axes and clock checks (fit.imu_agreement), then the rest."""
        if retracked and not self.contradicts:
            findings = [
                f"the frames were tracked again without the gyro's predictions (with them the images measured "
                f"too little to check it); {self.disagreeing} of {self.judged} confident frame pairs disagree with "
                "it"
            ] + findings
        if self.contradicts:
            again = "; the frames were tracked again without it" if retracked else ""
            said = f"the gyro is not used: {self._why()}{again}"
            if self.scaled_alike:
                return [f"{said}. {self._scale_hint()}"] + findings
            if not findings:
                return [
                    f"{said}. Check its units (rad/s), signs, axes (run.imu_rotvec_cam) and clock (run.imu_time_offset_s)"
                ]
            return [f"{said}; {findings[0]}"] + findings[1:]
        findings = self._still_warnings() + self._short_warnings() + findings
        if not self.can_tell:
            return [
                f"the gyro is used unchecked: the images measured {self.judged} turning frame pairs confidently, "
                f"at least {MIN_JUDGED_PAIRS} are needed to check it"
            ] + findings
        return findings

    def _still_warnings(self) -> list[str]:
        """One line when the events turned over pairs where the gyro reads still."""
        if not self.still:
            return []
        frames, off = zip(*self.still)
        return [
            f"the events' rotation turns while the gyro reads still, beyond the noise of both, over {len(frames)} "
            f"of {self.compared} frame pairs (frames {frames[0]}-{frames[-1]}, up to {np.degrees(max(off)):.2f} deg "
            "apart): the scene moves before a still camera (independent motion), or the gyro measures nothing; "
            "those frames are weak"
        ]

    def _short_warnings(self) -> list[str]:
        """One line when the fit is off over too short a span to refute the gyro (fit_off, not contradicts)."""
        if not self.fit_off or self.contradicts:
            return []
        return [
            (
                f"the gyro is used, though {self._why()}: those pairs span {self.judged_span_s:.2f} s, too short to "
                f"tell a gyro's scale or bias from the images' own systematic errors (at least {MIN_FIT_SPAN_S:g} s "
                "are needed); a longer window checks it"
            )
        ]

    def _scale_hint(self) -> str:
        """What one scale between the gyro and the images points at (scaled_alike)."""
        return (
            f"Turning about the same axes ({self.judged - self.rescaled_disagreeing} of {self.judged} pairs agree once "
            "scaled), the two are one scale apart: check the camera's focal length first (the images' rotations "
            f"scale with 1 / focal_px; it looks {1 / self.scale:.2f} times the calibration's: a calibration of another "
            "resolution or binning), then the gyro's full-scale setting; not its axes, signs or clock"
        )

    def _why(self) -> str:
        if self.disagreeing > self.judged / 2 and not self.scaled_alike:
            return (
                f"{self.disagreeing} of {self.judged} confidently measured frame pairs disagree with it "
                f"(median {self.median_off_deg:.2f} deg apart)"
            )
        if self.scale_off:
            return (
                f"it turns {self.scale:.2f} times as far as the images over {self.judged} confidently measured "
                f"frame pairs (+-{self.scale_se:.2f}; a MEMS gyro is within a few percent)"
            )
        return (
            f"it reads {self.bias_rad_s:.3f} rad/s (+-{self.bias_se_rad_s:.3f}) more than the images turn, "
            f"constantly, over {self.judged} confidently measured frame pairs: a bias beyond the pose graph's "
            "prior (calibrate it, or set backend.gyro_bias_sigma)"
        )


def confident_steps(t: np.ndarray, edges, imu: ImuSeries) -> tuple[list, np.ndarray, np.ndarray]:
    """The consecutive, non-loop edges with CONFIDENT_INLIERS or more over intervals of frame
    times `t` [s] that last some time and the gyro measures (ImuSeries.covered), with the
    images' and the gyro's rotations over them, (N, 3, 3) each."""
    steps = [e for e in edges if e.j == e.i + 1 and not e.loop and e.inliers >= CONFIDENT_INLIERS]
    t0, t1 = np.array([t[e.i] for e in steps], float), np.array([t[e.j] for e in steps], float)
    steps = [e for e, m in zip(steps, imu.covered(t0, t1) & (t1 > t0)) if m]
    if not steps:
        return [], np.empty((0, 3, 3)), np.empty((0, 3, 3))
    R_gyro = np.stack([gyro_rotation(imu, t[e.i], t[e.j]) for e in steps])
    return steps, np.stack([e.R_i_j for e in steps]), R_gyro


def judge_gyro(t: np.ndarray, edges, imu: ImuSeries) -> GyroVerdict:
    """Compare the confident consecutive edges' rotations (confident_steps) with the gyro's over
    the same intervals, as configured (no axes or clock fitted), less the pairs over which the
    gyro reads still while the edge turns (still_gyro_pairs: a moving scene convicts no gyro):
    GyroVerdict."""
    compared, still = still_gyro_pairs(t, edges, imu)
    noted = {"still": tuple((e.j, off) for e, off in still), "compared": compared}
    steps, R_vision, R_gyro = confident_steps(t, without(edges, {e.j for e, _ in still}), imu)
    judged, disagree, off = disagreement(R_gyro, R_vision)
    if not judged.any():
        return GyroVerdict(0, 0, float("nan"), **noted)
    dt = np.array([t[e.j] - t[e.i] for e in steps])[judged]
    v = matrix_to_rotvec(R_vision[judged])
    fitted = _scale_and_bias(v, matrix_to_rotvec(R_gyro[judged]), dt)
    rescaled_disagreeing = int(disagreement(R_gyro[judged], rotvec_to_matrix(v * fitted[0]))[1].sum())
    pairs = [e for e, m in zip(steps, judged) if m]
    span = float(t[pairs[-1].j] - t[pairs[0].i])
    return GyroVerdict(
        int(judged.sum()),
        int(disagree.sum()),
        float(np.degrees(np.median(off[judged]))),
        *fitted,
        span,
        rescaled_disagreeing,
        **noted,
    )


def still_gyro_pairs(t: np.ndarray, edges, imu: ImuSeries) -> tuple[int, list[tuple[RelativeRotation, float]]]:
    """The consecutive, non-loop edges over frame times `t` [s] whose estimator states its own
    covariance (RelativeRotation.covariance) over intervals the
    gyro measures: how many there are, and those over which the gyro reads still while the
    edge turns, with the angle [rad] between the two rotations.

    The gyro reads still over a pair when its rotation vector is within CHI2_3_999 of its own
    noise (GYRO_NOISE_DENSITY, GYRO_BIAS_RAD_S, per axis). An edge there turns when its
    rotation differs from the gyro's by more than CHI2_3_999 of both noises added (its sigma
    and the gyro's), alone or over the stretch of consecutive still pairs it belongs to (their
    chained rotations against the gyro's over the stretch, the edges' variances summed and the
    gyro's taken over the whole span, its bias growing with it), where it then differs by more
    than both noises' mean (3 variances: a slow turn beyond noise over a stretch, not within
    each pair). Both the gyro's stillness and the turn are needed: an estimator's sigma holds
    its errors' RMS but not their tails (docs/imu.md measures cmax's on a turning camera),
    while a gyro's noise is what its model says, so only where the gyro says still is an edge
    turning beyond both no error of its own."""
    steps = [e for e in edges if e.j == e.i + 1 and not e.loop and e.covariance is not None]
    steps = [e for e in steps if t[e.j] > t[e.i] and imu.covered(t[e.i], t[e.j])]
    still = []  # (edge, R_gyro, gyro variance per axis [rad^2], rotation vector apart [rad])
    for e in steps:
        R_gyro = gyro_rotation(imu, t[e.i], t[e.j])
        variance = _gyro_variance(t[e.j] - t[e.i])
        g = matrix_to_rotvec(R_gyro)
        if g @ g <= CHI2_3_999 * variance:
            still.append((e, R_gyro, variance, matrix_to_rotvec(R_gyro.T @ e.R_i_j)))
    found = []
    for stretch in _consecutive(still):
        first, last = stretch[0][0], stretch[-1][0]
        R_edges = functools.reduce(np.matmul, [e.R_i_j for e, *_ in stretch])
        apart = matrix_to_rotvec(gyro_rotation(imu, t[first.i], t[last.j]).T @ R_edges)
        covariance = _gyro_variance(t[last.j] - t[first.i]) * np.eye(3) + sum(e.covariance for e, *_ in stretch)
        turned = apart @ np.linalg.solve(covariance, apart) > CHI2_3_999
        for e, _, gyro_var, d in stretch:
            noise = gyro_var * np.eye(3) + e.covariance
            if d @ np.linalg.solve(noise, d) > (3.0 if turned else CHI2_3_999):
                found.append((e, float(np.linalg.norm(d))))
    return len(steps), found


def _gyro_variance(dt: float) -> float:
    """The per-axis variance [rad^2] of the gyro's rotation over dt [s] (GYRO_NOISE_DENSITY, GYRO_BIAS_RAD_S)."""
    return GYRO_NOISE_DENSITY**2 * dt + (GYRO_BIAS_RAD_S * dt) ** 2


def _consecutive(pairs: list) -> list[list]:
    """`pairs` ((edge, ...) in frame order) cut where one does not start at the frame the previous ends."""
    stretches = []
    for pair in pairs:
        if stretches and stretches[-1][-1][0].j == pair[0].i:
            stretches[-1].append(pair)
        else:
            stretches.append([pair])
    return stretches


def without(edges, frames) -> list:
    """`edges` less the consecutive, non-loop ones ending at `frames` (a set of j)."""
    return [e for e in edges if not (e.j == e.i + 1 and not e.loop and e.j in frames)]


def _scale_and_bias(v: np.ndarray, g: np.ndarray, dt: np.ndarray) -> tuple[float, float, float, float]:
    """g = scale v + bias dt for rotation vectors v (the images') and g (the gyro's) (N, 3) [rad]
    over intervals dt (N,) [s], by least squares: the scale, its standard error, the bias's norm
    [rad/s] and its standard error (the largest axis's)."""
    A = np.zeros((3 * len(v), 4))
    A[:, 0] = v.ravel()
    for axis in range(3):
        A[axis::3, 1 + axis] = dt
    if len(v) < 3 or np.linalg.matrix_rank(A) < 4:
        return 1.0, np.inf, 0.0, np.inf
    x, *_ = np.linalg.lstsq(A, g.ravel(), rcond=None)
    residual = g.ravel() - A @ x
    covariance = residual @ residual / (len(residual) - 4) * np.linalg.inv(A.T @ A)
    se = np.sqrt(np.diag(covariance))
    return float(x[0]), float(se[0]), float(np.linalg.norm(x[1:])), float(se[1:].max())


def disagreement(R_gyro: np.ndarray, R_vision: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For rotations over the same intervals (N, 3, 3): which pairs turned enough to compare
    (MIN_TURN_RAD), which of those disagree (DISAGREEMENT) and the angle between the two [rad]."""
    identity = np.eye(3)
    turned = np.maximum(geodesic_angle(identity, R_vision), geodesic_angle(identity, R_gyro))
    off = geodesic_angle(R_gyro, R_vision)
    judged = turned >= MIN_TURN_RAD
    return judged, judged & (off > DISAGREEMENT * turned), off
