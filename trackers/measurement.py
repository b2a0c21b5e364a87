"""What every tracker shares: turning matched pixels into a relative rotation with the shared
two-view geometry, and judging whether that measurement is weak. Not a plugin."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.geometry.covariance import METHODS as COVARIANCE_METHODS
from eas_vo.geometry.rotations import matrix_to_rotvec
from eas_vo.geometry.two_view import ESSENTIAL_METHODS, GEOMETRIES, bearings, explains, rotation_from_correspondences
from eas_vo.types import FrameRecord, RelativeRotation
from eas_vo.validation import check_choice, check_range

#: The focal length [px] a tracker's extents in pixels are stated for: the DAVIS240's, whose
#: images the defaults were set on. A tracker converts them to its camera by PixelScale, so a
#: view seen through more pixels (a larger sensor of the same field of view) is tracked alike:
#: its corners as far apart in angle, its corner and flow windows and its pyramid as wide.
#: Precisions in pixels (inlier thresholds, residuals, LK's step and forward-backward
#: tolerances) stay the sensor's: a pixel's measurement noise does not grow with the sensor.
REFERENCE_FOCAL_PX = 200.0


@dataclass(frozen=True)
class PixelScale:
    """Converts extents stated at REFERENCE_FOCAL_PX to a camera of `factor` times that focal
    length. Lengths scale in proportion; a pyramid gains (or loses) a level per whole octave
    of the factor (`octaves`, rounded towards zero) and its window takes the rest, so the
    coarsest level and its window see the same angles (a 2x copy of the images is tracked as
    the original, one level down) and a window is never more than halved or doubled."""

    factor: float

    @classmethod
    def of(cls, camera: CameraModel | None) -> "PixelScale":
        return cls(1.0 if camera is None else camera.focal_px / REFERENCE_FOCAL_PX)

    @property
    def octaves(self) -> int:
        return int(math.log2(self.factor))

    def length(self, px: float) -> float:
        return px * self.factor

    def corners(self, min_distance_px: float, block_size: int) -> tuple[float, int]:
        """Shi-Tomasi's (min_distance [px], block_size [px]) for this camera."""
        return self.length(min_distance_px), max(3, round(self.length(block_size)))

    def pyramid(self, levels: int, window_px: int) -> tuple[int, int]:
        """(levels, window [px]) of a pyramid stated as `levels` above the full image with
        `window_px` per level."""
        return max(0, levels + self.octaves), max(3, round(window_px * self.factor / 2.0**self.octaves))

    def extents(self, config) -> "TrackingExtents":
        """A KLT-like `config`'s (a frozen dataclass) corner and flow extents, stated at
        REFERENCE_FOCAL_PX, for this camera: `min_distance_px` and `block_size` (corners),
        `lk_max_level` and `lk_win_size` (flow)."""
        min_distance_px, block_size = self.corners(config.min_distance_px, config.block_size)
        lk_max_level, lk_win_size = self.pyramid(config.lk_max_level, config.lk_win_size)
        return TrackingExtents(min_distance_px, block_size, lk_max_level, lk_win_size)


@dataclass(frozen=True)
class TrackingExtents:
    """Shi-Tomasi's and pyramidal Lucas-Kanade's extents in one camera's pixels (PixelScale.extents)."""

    min_distance_px: float  # between two corners [px]
    block_size: int  # a corner's block [px]
    lk_max_level: int  # pyramid levels above the full image
    lk_win_size: int  # the flow's window at each level [px]


#: How StepBound's reason ends (after the angle [deg]).
STEP_BOUND_REASON = "deg from the last ok step's rate"
#: The predicted error [px of focal length] above which a step is reported `weak`
#: (TwoViewConfig.max_predicted_error_px). Chosen with paper.toml on the choice data
#: (synthetic:default with eas, histeq and ts, the real excerpt shapes_rotation's first 20 s with
#: histeq and original; benchmarks/status_calibration.py): among the bounds calling at most 25 %
#: of the right steps (error under 0.7 px of focal length) weak, the one calling the fewest
#: wrong ones (over 3.5 px) ok. The covariances are geometry.covariance.SCALE's; see
#: docs/frame_status.md for the rates on held-out data.
MAX_PREDICTED_ERROR_PX = 3.3


@dataclass(frozen=True)
class TwoViewConfig:
    """Geometry and quality settings of a tracker's measurements.

    Attributes:
        geometry: `essential` (the paper: five-point essential matrix), `rotation` (rotation-only
            2-point RANSAC and least squares on bearings), `auto` (the better by GRIC) or
            `homography` (a plane's homography: for loops, whose views lie centimetres apart).
        essential_method: robust estimator around OpenCV's five-point solver: `usac` (RANSAC
            with local optimisation, the default), `ransac` (plain), `magsac`, `lmeds`.
        ransac_threshold_px: inlier threshold [px].
        ransac_confidence: success probability.
        min_inliers, min_inlier_ratio, max_residual_px: a measurement with fewer inliers, a
            lower inlier ratio or a larger inlier noise (per-axis sigma from the median
            residual [px]) is weak to the tracker (`weakness`): `measure` drops it where its
            rotation does not explain its correspondences, StepBound holds it to the motion
            before it, and the fallbacks run on it. The frame's reported status reads the
            covariance instead (`max_predicted_error_px`), except for `min_inliers`. The ratio
            and the residual were set, with the paper's configuration, to call at most 10 % of
            the right measurements weak (docs/frame_status.md, "Rates": before).
            The residual is in pixels, not per focal length: LK's localisation noise and the
            1 px inlier threshold it is cut at are properties of image patches in pixels.
            15 inliers is three times the five-point minimum (a count follows the scene's
            corners, so data cannot calibrate it for every frontend).
        max_angular_acceleration_deg_s2: a step whose rotation departs from the rate of the
            last `ok` step by more than this acceleration allows is doubted (StepBound). The
            default lies above the most abrupt rotations a person's head is put through
            (docs/frame_status.md cites the measurements); raise it for a drone or a vehicle.
        covariance: how a measurement's covariance is estimated from its inliers:
            `information` or `bootstrap` (geometry.covariance; docs/uncertainty.md).
        max_predicted_error_px: the frame status a run reports (`status`): a step whose
            predicted error, the largest 1-sigma of its covariance times the focal length
            [px of focal length, so that it means the same on every sensor], is above this is
            reported `weak`. Chosen with the paper's configuration on the choice data
            (benchmarks/status_calibration.py; docs/frame_status.md). Only the label: what
            the tracker decides (measure's drop, StepBound, the fallbacks) reads `weakness`.
    """

    geometry: str = "essential"
    essential_method: str = "usac"
    ransac_threshold_px: float = 1.0
    ransac_confidence: float = 0.999
    min_inliers: int = 15
    min_inlier_ratio: float = 0.55
    max_residual_px: float = 0.6
    max_angular_acceleration_deg_s2: float = 10_000.0
    covariance: str = "information"
    max_predicted_error_px: float = MAX_PREDICTED_ERROR_PX

    def validate(self) -> None:
        check_choice(self, "geometry", GEOMETRIES)
        check_choice(self, "essential_method", ESSENTIAL_METHODS)
        check_range(self, "ransac_threshold_px", 0.0, 100.0, lo_open=True)
        check_range(self, "ransac_confidence", 0.0, 1.0, lo_open=True)
        check_range(self, "min_inliers", 0, 100_000)
        check_range(self, "min_inlier_ratio", 0.0, 1.0)
        check_range(self, "max_residual_px", 0.0, 100.0, lo_open=True)
        check_range(self, "max_angular_acceleration_deg_s2", 0.0, 1e9, lo_open=True)
        check_choice(self, "covariance", COVARIANCE_METHODS)
        check_range(self, "max_predicted_error_px", 0.0, 1000.0, lo_open=True)


def measure(
    config: TwoViewConfig, camera: CameraModel, pts_from_px: np.ndarray, pts_to_px: np.ndarray, i: int, j: int
) -> RelativeRotation | None:
    """The rotation R_i_j from pixel positions [px] of the same points in frames i and j
    (undistorted first), with its quality; None when no model is found, or the model is one
    its own tracker doubts too much to use:

    - an essential matrix with fewer than `min_inliers` inliers: support a robust fit finds
      by chance (the five-point solver fits any 5 points, and hundreds of hypotheses find a
      few more within a pixel of their epipolar lines: a band across the image, where the
      rotation and homography models need a point within a pixel of a point; what such
      steps did: docs/frame_status.md);
    - weak otherwise, with a rotation that does not explain the correspondences (all of
      them, two_view.explains): it turns them far further than they moved.

    A weak step that is kept turns the bearings by at most about three times their median
    motion; a step that is not weak has its model's own support (the paper's estimate).
    """
    return measure_with_inliers(config, camera, pts_from_px, pts_to_px, i, j)[0]


def measure_with_inliers(
    config: TwoViewConfig, camera: CameraModel, pts_from_px: np.ndarray, pts_to_px: np.ndarray, i: int, j: int
) -> tuple[RelativeRotation | None, np.ndarray]:
    """`measure`'s rotation and which of the N correspondences its model counts as inliers,
    (N,) bool (all False when it returns None)."""
    none = np.zeros(len(pts_from_px), bool)
    x_from, x_to = camera.undistort(pts_from_px), camera.undistort(pts_to_px)
    threshold = config.ransac_threshold_px / camera.focal_px
    found = rotation_from_correspondences(
        x_from, x_to, threshold, config.ransac_confidence, config.essential_method, config.geometry, config.covariance
    )
    if found is None or (found.model == "essential" and found.inliers < config.min_inliers):
        return None, none
    edge = RelativeRotation(
        i,
        j,
        found.R_prev_cur,
        found.inliers,
        found.inliers / max(len(pts_from_px), 1),
        found.residual,
        covariance=found.covariance,
    )
    if weakness(config, edge, camera.focal_px) and not explains(
        found.R_prev_cur.T, bearings(x_from), bearings(x_to), threshold
    ):
        return None, none
    return edge, found.inlier_mask


def weakness(config: TwoViewConfig, edge: RelativeRotation, focal_px: float) -> str:
    """Why `edge` is a weak measurement ("" if it is not)."""
    if edge.inliers < config.min_inliers:
        return f"few inliers ({edge.inliers} < {config.min_inliers})"
    if edge.inlier_ratio < config.min_inlier_ratio:
        return f"low inlier ratio ({edge.inlier_ratio:.2f} < {config.min_inlier_ratio})"
    if edge.residual_rad * focal_px > config.max_residual_px:
        return f"large residual ({edge.residual_rad * focal_px:.2f} px > {config.max_residual_px})"
    return ""


def frame_record(
    config: TwoViewConfig,
    camera: CameraModel,
    k: int,
    t: float,
    nc: int,
    step: RelativeRotation | None,
    redetected: bool,
    enough_correspondences: bool,
) -> FrameRecord:
    """The record of frame k at `t` [s] with `nc` correspondences and its frame-to-frame
    measurement `step` (None: nothing measured, because there were not enough correspondences
    to try or because no model was found): `ok`, `weak` or `lost`, with the reason."""
    if step is None:
        reason = "no model" if enough_correspondences else "few correspondences"
        return FrameRecord(k, t, nc, 0, "lost", redetected, reason=reason)
    why = weakness(config, step, camera.focal_px)
    return FrameRecord(
        k,
        t,
        nc,
        step.inliers,
        "weak" if why else "ok",
        redetected,
        step.inlier_ratio,
        step.residual_rad * camera.focal_px,
        why,
    )


def predicted_error_px(edge: RelativeRotation, focal_px: float) -> float:
    """The error a step's own covariance predicts [px of focal length]: its largest 1-sigma
    (RelativeRotation.sigma_rad) times the focal length."""
    return edge.sigma_rad * focal_px


def status(config: TwoViewConfig, record: FrameRecord, step: RelativeRotation | None, focal_px: float) -> FrameRecord:
    """The record a run reports for a frame the tracker has finished with (`record` as its
    decisions left it, `step` its frame-to-frame edge): a measured frame is `weak` with fewer
    than `min_inliers` inliers, a predicted error (predicted_error_px) above
    `max_predicted_error_px`, or a step StepBound doubted (STEP_BOUND_REASON), else `ok`;
    other statuses stay. The label only: every decision (measure's drop of a weak step,
    StepBound, the fallbacks' triggers) is taken on `weakness` before it, so trajectories do
    not depend on it."""
    if record.status not in ("ok", "weak") or step is None:
        return record
    if step.inliers < config.min_inliers:  # weakness's first reason: the record says so already
        return replace(
            record, status="weak", reason=record.reason or f"few inliers ({step.inliers} < {config.min_inliers})"
        )
    predicted = predicted_error_px(step, focal_px)
    if not predicted <= config.max_predicted_error_px:
        return replace(
            record, status="weak", reason=f"predicted error ({predicted:.2f} px > {config.max_predicted_error_px:g} px)"
        )
    if STEP_BOUND_REASON in record.reason:  # a confident step the motion before it contradicts
        return replace(record, status="weak")
    return replace(record, status="ok", reason="")


class StepBound:
    """What a step may say, given the steps before it: the frame-to-frame rotation must lie
    within `a * dt * (t_mid - t_ref)` [rad] (plus three inlier thresholds of measurement noise)
    of the rotation at the last `ok` step's rate, `a` the config's largest angular acceleration
    [rad/s^2], dt the frame interval [s] and t_mid - t_ref the time between the two steps'
    midpoints [s]: a step farther off would need a faster change of rate than the motion can
    have. Such an `ok` step becomes `weak` (kept: the images may show it, as a camera's image
    turned upside down does, but it is not confident), a `weak` one `lost` (its edges dropped).
    Without an `ok` step before it a step stands. One per tracker, fed every frame in order."""

    def __init__(self, config: TwoViewConfig, camera: CameraModel | None):
        self._acceleration = math.radians(config.max_angular_acceleration_deg_s2)
        self._noise_rad = 3.0 * config.ransac_threshold_px / (REFERENCE_FOCAL_PX if camera is None else camera.focal_px)
        self._rate: tuple[np.ndarray, float] | None = None  # (rotation vector per second [rad/s], midpoint [s])

    def judge(
        self, record: FrameRecord, edges: list[RelativeRotation], t_prev: float, t: float
    ) -> tuple[FrameRecord, list[RelativeRotation]]:
        """Frame `record`'s (record, edges), measured over [t_prev, t] [s], kept or made `lost`."""
        step = next((e for e in edges if e.j == record.index and e.i == record.index - 1), None)
        if step is None or record.status not in ("ok", "weak"):
            return record, edges
        dt, mid = t - t_prev, 0.5 * (t + t_prev)
        rotvec = matrix_to_rotvec(step.R_i_j)
        departure = bound = 0.0
        if self._rate is not None:
            rate, t_ref = self._rate
            departure = float(np.linalg.norm(rotvec - rate * dt))
            bound = self._acceleration * dt * (mid - t_ref) + self._noise_rad
        if departure <= bound:
            if record.status == "ok":
                self._rate = (rotvec / dt, mid)
            return record, edges
        why = f"{math.degrees(departure):.1f} {STEP_BOUND_REASON} (more than {math.degrees(bound):.1f} deg)"
        if record.status == "ok":
            return replace(record, status="weak", reason=why), edges
        return replace(record, status="lost", inliers=0, reason=f"{record.reason}, and {why}"), []
