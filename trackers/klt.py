"""`klt`, the paper's tracker: Shi-Tomasi corners, pyramidal Lucas-Kanade flow from frame
to frame, five-point essential matrix, thresholds 1 and 2 -- and, off by default, what keeps
it on track through fast motion: LK started from a predicted rotation (gyro or constant
angular velocity), a forward-backward check, and a fallback where LK's measurement falls short
(descriptor matching, or an alignment of the whole images).

It only ever sees uint8 images; the geometry is the shared `eas_vo.geometry.two_view`.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, replace
from typing import Callable

import cv2
import numpy as np

from eas_vo import concurrency
from eas_vo.camera import CameraModel
from eas_vo.errors import ConfigError
from eas_vo.geometry.rotations import geodesic_angle, gyro_rotation, scaled_rotation
from eas_vo.plugins import Tracker
from eas_vo.trackers.alignment import FINEST_PIXEL_RAD, FallbackAudit, PhotometricAlignment
from eas_vo.trackers.features import DETECTORS, Features, RefinedMatching
from eas_vo.trackers.loops import LoopCloser, LoopClosureConfig
from eas_vo.trackers.measurement import (
    PixelScale,
    StepBound,
    TwoViewConfig,
    frame_record,
    measure,
    measure_with_inliers,
    status,
    weakness,
)
from eas_vo.trackers.motion import lk_params, lk_track
from eas_vo.types import FrameRecord, ImuSeries, RelativeRotation
from eas_vo.validation import check_choice, check_range

PREDICTIONS = ("none", "gyro", "velocity", "auto")
FALLBACKS = ("none", "match", "align")
#: No correspondences: (where they were, where LK tracked them), each (0, 2) [px].
_NO_PAIRS = (np.empty((0, 2), np.float32), np.empty((0, 2), np.float32))


@dataclass(frozen=True)
class KltConfig(LoopClosureConfig, TwoViewConfig):
    """Corner detection and optical flow settings, (TwoViewConfig) the geometry and
    (LoopClosureConfig) loop closure. docs/method.md#fast-motion describes the options that are
    off by default, docs/best_config.md what they give.

    Attributes:
        max_corners, quality_level, min_distance_px, block_size: Shi-Tomasi detection.
        lk_win_size, lk_max_level: pyramidal Lucas-Kanade window [px] and pyramid levels.
            These four extents are stated for a 200 px focal length (the DAVIS240's); the
            tracker converts them to its camera (measurement.PixelScale).
        lk_max_iterations, lk_epsilon_px: each pyramid level stops after this many iterations
            or once a step is shorter than this [px] (OpenCV's defaults 30 and 0.01).
        threshold1: with fewer correspondences the previous rotation is kept.
        threshold2: with fewer correspondences corners are detected again in the frame.
        keyframe_interval: 0 (the paper) or N: also measure the rotation from a keyframe to
            each frame with the corners tracked since it, a new keyframe every N frames and
            at each redetection (multi-frame edges i -> j for the gtsam backend).
        predict: where LK starts each corner: `none` (where it was: the paper), `gyro` (moved
            by the rotation the gyro measured since the previous frame, in the camera frame),
            `velocity` (by the last measured rotation, scaled to this frame interval) or `auto`
            (gyro when the dataset has an IMU, else velocity).
        fb_max_px: 0 (the paper) or the forward-backward check: a corner tracked back into the
            previous frame must land within this many pixels of where it started.
        fallback: what measures a frame LK's measurement falls short on (where it replaces
            LK's, corners are detected again): `none` (the paper). `match`: where the frame is
            `weak` (for any reason: LK lost on a large turn is often weak by its inlier ratio
            alone) or `lost`, matched descriptors (`fallback_detector`) refined by LK
            (features.RefinedMatching), kept if not weak and more certain
            (RelativeRotation.sigma_rad); docs/best_config.md#each-tracker-on-the-real-excerpt.
            `align`: where LK's step is missing or has under `min_inliers` inliers and no gyro
            predicted it (LK then failed on the images themselves, which aligning them rarely
            repairs), the two views aligned by their intensities and LK retried from that
            rotation (KltTracker._aligned_step), judged over the run by alignment.FallbackAudit;
            docs/best_config.md#how-the-fallback-works.
        fallback_detector: the `match` fallback's keypoints, `orb` or `sift`.
    """

    max_corners: int = 500
    quality_level: float = 0.01
    min_distance_px: float = 7.0
    block_size: int = 7
    lk_win_size: int = 21
    lk_max_level: int = 3
    lk_max_iterations: int = 30
    lk_epsilon_px: float = 0.01
    threshold1: int = 10
    threshold2: int = 150
    keyframe_interval: int = 0
    predict: str = "none"
    fb_max_px: float = 0.0
    fallback: str = "none"
    fallback_detector: str = "orb"

    def validate(self) -> None:
        TwoViewConfig.validate(self)
        LoopClosureConfig.validate(self)
        check_choice(self, "predict", PREDICTIONS)
        check_range(self, "fb_max_px", 0.0, 100.0)
        check_choice(self, "fallback", FALLBACKS)
        check_choice(self, "fallback_detector", DETECTORS)
        check_range(self, "max_corners", 1, 100_000)
        check_range(self, "quality_level", 0.0, 1.0, lo_open=True)
        check_range(self, "min_distance_px", 0.0, 1000.0)
        check_range(self, "block_size", 3, 99)
        check_range(self, "lk_win_size", 3, 201)
        check_range(self, "lk_max_level", 0, 10)
        check_range(self, "lk_max_iterations", 1, 1000)
        check_range(self, "lk_epsilon_px", 0.0, 10.0, lo_open=True)
        check_range(self, "threshold1", 5, 100_000)
        check_range(self, "threshold2", 5, 100_000)
        check_range(self, "keyframe_interval", 0, 100_000)
        if self.threshold1 > self.threshold2:
            raise ConfigError(f"threshold1 ({self.threshold1}) must not exceed threshold2 ({self.threshold2})")


@dataclass(frozen=True)
class _View:
    """The image a frame is tracked from, as the tracker held it then."""

    image: np.ndarray
    pts: np.ndarray  # the corners tracked from it, (N, 2) [px]
    corners: np.ndarray | None  # its Shi-Tomasi corners [px], when they were detected in it


@dataclass
class _Frame:
    """A frame from its tracking to its result: what the steps after its two-view geometry read."""

    k: int
    t: float  # [s]
    t_prev: float  # the previous frame's time [s]
    image: np.ndarray
    previous: _View
    predicted: np.ndarray | None  # R_{k-1}_{k} LK started from (None: no prediction)
    nc: int  # corners tracked into the frame
    geometry: Future  # _measured's (record, edges, step)
    result: tuple[FrameRecord, list[RelativeRotation]] | None = None  # once finished


class KltTracker(Tracker):
    """Tracks corners frame to frame and measures the relative rotation of each pair.

    Its `config` is the one given; `extents` holds its extents in pixels converted to its camera
    (measurement.PixelScale). Feed frames in order with `process` or `submit`; each gives what
    happened and the measured rotations: `R_{k-1}_{k}` between the previous and this frame (the
    paper) and, with `keyframe_interval` > 0, `R_{kf}_{k}` from the corners tracked since the
    keyframe kf.

    One per-frame path, `submit` (`process` takes its result at once): the frame is tracked, its
    two-view geometry is started as a future (on another thread when there are several), and the
    steps after the geometry (`_after_geometry`: the fallback, the step bound, loop closing) run
    in frame order, in the caller's thread, when the result is taken. What the next frame's
    tracking reads of them (the last step a velocity prediction extrapolates, whether a fallback
    detected corners afresh) it reads only after `_finish` ran them, so taking a result later
    changes nothing but the time (tests/trackers/test_klt.py tries every choice of KltConfig).
    """

    name = "klt"
    description = "Shi-Tomasi corners, pyramidal Lucas-Kanade, five-point essential matrix (the paper)"
    Config = KltConfig

    def __init__(
        self, config: KltConfig | None = None, camera: CameraModel | None = None, *, imu: ImuSeries | None = None
    ):
        super().__init__(config, camera, imu=imu)
        self.extents = PixelScale.of(camera).extents(self.config)
        c, e = self.config, self.extents
        self._lk_params = lk_params(e.lk_win_size, e.lk_max_level, c.lk_max_iterations, c.lk_epsilon_px)
        self._predict = c.predict if c.predict != "auto" else ("gyro" if imu is not None else "velocity")
        self._matching = (
            RefinedMatching(Features(c.fallback_detector), camera, c, c.min_inliers) if c.fallback == "match" else None
        )
        self._alignment = PhotometricAlignment(camera) if c.fallback == "align" else None

    def reset(self) -> None:
        """Forget every frame seen; the next frame is a first frame."""
        self._prev_image: np.ndarray | None = None
        self._prev_pts = np.empty((0, 2), np.float32)
        self._prev_corners: np.ndarray | None = None  # the previous image's Shi-Tomasi corners, when they were detected
        self._prev_detected: tuple | None = None  # the previous image's keypoints, when the fallback detected them
        self._prev_pyramid: dict | None = None  # the previous image undistorted, when the alignment made it
        self._kf_pts = np.empty((0, 2), np.float32)  # where each tracked corner was in the keyframe
        self._kf_index = 0
        self._k = -1
        self._last_step: tuple[np.ndarray, float] | None = None  # (R_{k-2}_{k-1}, its interval [s]) for velocity
        self._last_pairs = _NO_PAIRS  # the corners tracked into the frame last given (tracked_points)
        self._unfinished: deque[_Frame] = deque()  # frames submitted whose steps after the geometry have not run
        self._loops = LoopCloser(self.config, self.camera) if self.config.loop_closure else None
        self._audit = FallbackAudit("align") if self.config.fallback == "align" else None
        self._bound = StepBound(self.config, self.camera)

    @property
    def needs_imu(self) -> bool:
        return self.config.predict == "gyro"

    @property
    def uses_imu(self) -> bool:
        return self.config.predict in ("gyro", "auto")

    @property
    def closes_loops(self) -> bool:
        return self.config.loop_closure

    @property
    def tracker_warnings(self) -> tuple[str, ...]:
        """What the run should say about this tracking: the `align` fallback turned off, with the
        frames that turned it off (alignment.FallbackAudit)."""
        return (self._audit.warning,) if self._audit is not None and self._audit.warning else ()

    def detect(self, image: np.ndarray) -> np.ndarray:
        """Shi-Tomasi corners of `image`, (N, 2) float32 [px]."""
        c, e = self.config, self.extents
        pts = cv2.goodFeaturesToTrack(image, c.max_corners, c.quality_level, e.min_distance_px, blockSize=e.block_size)
        return np.empty((0, 2), np.float32) if pts is None else pts.reshape(-1, 2).astype(np.float32)

    def track(self, image: np.ndarray, R_prev_cur: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """LK-track the previous corners into `image`, from the predicted rotation if any
        (motion.lk_track): (N, 2) positions [px] and a mask of the tracked ones."""
        return lk_track(
            self.camera, self._prev_image, self._prev_pts, image, self._lk_params, R_prev_cur, self.config.fb_max_px
        )

    def predicted_rotation(self, t_prev: float, t: float) -> np.ndarray | None:
        """R_{k-1}_{k} expected before measuring it (None: no prediction, as the paper)."""
        if self._predict == "gyro" and self.imu is not None:
            return gyro_rotation(self.imu, t_prev, t)
        if self._predict == "velocity":
            self._finish()  # the last step is the last frame's, once its steps after the geometry ran
            if self._last_step is not None:
                R_last, dt_last = self._last_step
                return scaled_rotation(R_last, (t - t_prev) / dt_last)
        return None

    def process(self, image: np.ndarray, t: float) -> tuple[FrameRecord, list[RelativeRotation]]:
        """Track into `image` (uint8, sensor size) taken at `t` [s]: `submit`'s result, taken at once."""
        return self.submit(image, t)()

    def submit(self, image: np.ndarray, t: float) -> Callable[[], tuple[FrameRecord, list[RelativeRotation]]]:
        """Track into `image` (uint8, sensor size) taken at `t` [s] and start its two-view
        geometry; returns the function that gives the frame's (record, edges)."""
        k, t_prev, done = self._begins(image, t)
        if done is not None:
            self._last_pairs = _NO_PAIRS
            return lambda: done
        previous = _View(self._prev_image, self._prev_pts, self._prev_corners)
        predicted = self.predicted_rotation(t_prev, t)
        cur, ok = self.track(image, predicted)
        nc = int(ok.sum())
        self._last_pairs = (self._prev_pts[ok], cur[ok])
        # the geometry runs beside the next frame's tracking, unless this frame's result decides
        # how the next one starts (a fallback may detect corners afresh: _redetects waits for it)
        start = concurrency.submit if self.config.fallback == "none" else concurrency.done_now
        geometry = start(self._measured, k, t, nc, self._prev_pts[ok], cur[ok], self._kf_pts[ok], self._kf_index)
        frame = _Frame(k, t, t_prev, image, previous, predicted, nc, geometry)
        self._unfinished.append(frame)
        self._advance(image, self._redetects(frame), cur, ok, k)
        return lambda: self._finish(frame)

    def tracked_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The corners LK tracked into the frame last given, (N, 2) [px], and which of them the
        two-view model fitted to them counts as inliers, (N,) bool: measured again
        (measurement.measure_with_inliers; the estimate is deterministic), all False below
        threshold1, where none is fitted. No corners for a first frame or a repeated time; a
        fallback's own correspondences are not shown."""
        pts_prev, pts_cur = self._last_pairs
        if len(pts_cur) < self.config.threshold1:
            return pts_cur, np.zeros(len(pts_cur), bool)
        return pts_cur, measure_with_inliers(self.config, self.camera, pts_prev, pts_cur, self._k - 1, self._k)[1]

    def _begins(self, image: np.ndarray, t: float) -> tuple[int, float, tuple | None]:
        """The frame's start: (its index, the previous frame's time [s], and for a first frame or
        a repeated time its whole result (record, edges), else None: it is to be tracked)."""
        self._k += 1
        k = self._k
        if self._prev_image is None:
            self._start_keyframe(image, self.detect(image))
            self._prev_t = t
            if self._loops is not None:
                self._loops.step(k, image, [], lost=False)
            return k, t, (FrameRecord(k, t, 0, 0, "first", True), [])
        if t <= self._prev_t:  # no time between the two: nothing to measure, the rotation is kept
            return k, self._prev_t, (FrameRecord(k, t, 0, 0, "same_time", False), [])
        t_prev, self._prev_t = self._prev_t, t
        return k, t_prev, None

    def _measured(
        self, k: int, t: float, nc: int, prev_pts: np.ndarray, cur: np.ndarray, kf_pts: np.ndarray, kf_index: int
    ) -> tuple[FrameRecord, list[RelativeRotation], RelativeRotation | None]:
        """Frame k's record, its edges (from the previous frame; from the keyframe, when
        keyframe_interval > 0) and its step from the previous frame, from the tracked corners
        (`prev_pts`, `kf_pts` -> `cur`; `nc` of them). Reads nothing that changes: it runs on
        another thread while the next frame is tracked."""
        c = self.config
        edges, step = [], None
        if nc >= c.threshold1:
            step = measure(c, self.camera, prev_pts, cur, k - 1, k)
            if step is not None:
                edges.append(step)
                if c.keyframe_interval > 0 and k - kf_index >= 2:
                    skip = measure(c, self.camera, kf_pts, cur, kf_index, k)
                    if skip is not None:
                        edges.append(skip)
        return frame_record(c, self.camera, k, t, nc, step, nc < c.threshold2, nc >= c.threshold1), edges, step

    def _redetects(self, frame: _Frame) -> bool:
        """Whether corners are detected afresh in `frame` for the next one: too few were tracked
        (threshold2), or a fallback replaced LK's measurement, known once the frame is finished."""
        if self.config.fallback == "none":
            return frame.nc < self.config.threshold2
        return self._finish(frame)[0].redetected

    def _finish(self, frame: _Frame | None = None) -> tuple[FrameRecord, list[RelativeRotation]] | None:
        """Run the steps after the geometry of the frames submitted, in their order, up to
        `frame` (all, when None); `frame`'s result."""
        while self._unfinished and (frame is None or frame.result is None):
            unfinished = self._unfinished.popleft()
            unfinished.result = self._after_geometry(unfinished)
        return None if frame is None else frame.result

    def _after_geometry(self, frame: _Frame) -> tuple[FrameRecord, list[RelativeRotation]]:
        """Frame's (record, edges) from its two-view geometry: the fallback where LK's measurement
        falls short, the step bound, the fallback's audit, the step a velocity prediction
        extrapolates, loop closing, and last the status the run reports (measurement.status:
        every decision before it reads the record's status by `weakness`)."""
        record, edges, step = frame.geometry.result()
        if self._matching is not None:
            record, edges, step = self._matched(frame, record, edges, step)
        aligned = False
        if self._alignment is not None:
            record, edges, step, aligned = self._aligned(frame, record, edges, step)
        record, edges = self._bound.judge(record, edges, frame.t_prev, frame.t)
        step = edges[0] if edges else None
        if self._audit is not None:
            self._audited(frame.k, frame.t_prev, frame.t, step, aligned and step is not None, record.status == "ok")
        self._last_step = (step.R_i_j, frame.t - frame.t_prev) if step is not None else None
        if self._loops is not None:
            edges = edges + self._loops.step(frame.k, frame.image, edges, lost=record.status == "lost")
        return status(self.config, record, step, self.camera.focal_px), edges

    def _advance(self, image: np.ndarray, redetected: bool, cur: np.ndarray, ok: np.ndarray, k: int) -> None:
        """This image becomes the previous one: corners detected anew, or those tracked kept."""
        c = self.config
        if redetected:
            self._start_keyframe(image, self.detect(image))
        else:
            self._prev_image, self._prev_pts, self._kf_pts, self._prev_corners = image, cur[ok], self._kf_pts[ok], None
            if c.keyframe_interval > 0 and k - self._kf_index >= c.keyframe_interval:
                self._kf_index, self._kf_pts = k, cur[ok]

    def _matched(
        self, frame: _Frame, record: FrameRecord, edges: list[RelativeRotation], step: RelativeRotation | None
    ) -> tuple[FrameRecord, list[RelativeRotation], RelativeRotation | None]:
        """The `match` fallback: where LK's frame is weak or lost, the rotation from matched
        descriptors refined by LK replaces LK's if it is more certain. (record, edges, step)."""
        detected = None
        if record.status in ("weak", "lost"):
            detect = self._matching.features.detect
            detected = detect(frame.image)
            previous = frame.previous
            previous_detected = self._prev_detected or detect(previous.image)
            matched, n_matched = self._matching.rotation(
                previous.image, previous.pts, previous_detected, frame.image, detected, frame.k - 1, frame.k
            )
            if matched is not None and (step is None or matched.sigma_rad < step.sigma_rad):
                step, edges = matched, [matched]
                record = frame_record(
                    self._matching.coarse, self.camera, frame.k, frame.t, n_matched, matched, True, True
                )
        self._prev_detected = detected
        return record, edges, step

    def _aligned(
        self, frame: _Frame, record: FrameRecord, edges: list[RelativeRotation], step: RelativeRotation | None
    ) -> tuple[FrameRecord, list[RelativeRotation], RelativeRotation | None, bool]:
        """The `align` fallback: where LK's step is missing or has under `min_inliers` inliers, no
        gyro predicted it and the audit left it on, `_aligned_step`. (record, edges, step, and
        whether the fallback's own step replaced LK's)."""
        c = self.config
        by_gyro = self._predict == "gyro" and frame.predicted is not None
        pyramid, aligned = None, None
        if not self._audit.off and not by_gyro and (step is None or step.inliers < c.min_inliers):
            pyramid = self._alignment.pyramid(frame.image)
            aligned = self._aligned_step(frame, pyramid, step)
            if aligned is not None:
                step, n_aligned = aligned
                edges = [step] if step is not None else []
                record = frame_record(
                    c, self.camera, frame.k, frame.t, n_aligned if step is not None else frame.nc, step, True, True
                )
                if step is None:
                    record = replace(record, reason="no rotation explains the two images clearly better than no motion")
                elif n_aligned == 0:
                    record = replace(record, reason="aligned by intensities alone (no correspondences)")
        self._prev_pyramid = pyramid
        return record, edges, step, aligned is not None

    def _audited(
        self, k: int, t_prev: float, t: float, step: RelativeRotation | None, by_fallback: bool, ok: bool
    ) -> None:
        """Frame k's step shown to the fallback's audit: the fallback's, LK's own where it is not
        weak (primary: evidence the fallback can be judged by), or neither."""
        kind = "fallback" if by_fallback else "primary" if ok and step is not None else "other"
        self._audit.observe(k, kind, None if step is None else step.R_i_j, t - t_prev)

    def _aligned_step(self, frame: _Frame, pyramid: dict, step: RelativeRotation | None):
        """A missing LK step, or one with too few inliers, replaced by direct alignment: the views
        aligned (from the prediction, if any, and from no motion), LK retried on the previous
        image's corners from that rotation; the retry if it is not weak and agrees with the
        alignment within alignment.FINEST_PIXEL_RAD, else whichever of the alignment alone (an
        edge without correspondences, with the photometric cost's covariance,
        PhotometricAlignment.covariance) and the retry explains the two images best, if better than
        LK's step. (The new step, its correspondence count), or None to keep LK's; (None, 0)
        where neither the alignment nor LK's step explains the two images clearly better than no
        motion (PhotometricAlignment.explains): no measurement."""
        align, previous, k = self._alignment, frame.previous, frame.k
        source = self._prev_pyramid or align.pyramid(previous.image)

        def score(R_prev_cur: np.ndarray) -> float:
            return align.score(source, pyramid, R_prev_cur)

        R_aligned = align.align(
            source, pyramid, [np.eye(3)] if frame.predicted is None else [frame.predicted, np.eye(3)]
        )
        if R_aligned is None:
            return None if step is None or align.explains(source, pyramid, step.R_i_j) else (None, 0)
        corners = self.detect(previous.image) if previous.corners is None else previous.corners
        cur, ok = lk_track(
            self.camera, previous.image, corners, frame.image, self._lk_params, R_aligned, self.config.fb_max_px
        )
        retried = (
            measure(self.config, self.camera, corners[ok], cur[ok], k - 1, k)
            if ok.sum() >= self.config.threshold1
            else None
        )
        if (
            retried is not None
            and not weakness(self.config, retried, self.camera.focal_px)
            and geodesic_angle(retried.R_i_j, R_aligned) <= FINEST_PIXEL_RAD
        ):
            return retried, int(ok.sum())
        candidates = [(RelativeRotation(k - 1, k, R_aligned), 0)] + (
            [(retried, int(ok.sum()))] if retried is not None else []
        )
        scores = [score(candidate[0].R_i_j) for candidate in candidates]
        best = int(np.argmax(scores))
        if scores[best] <= -1.0 or (step is not None and score(step.R_i_j) >= scores[best]):
            return None
        if best == 0:  # the alignment alone: the photometric cost's covariance
            return replace(candidates[0][0], covariance=align.covariance(source, pyramid, R_aligned)), 0
        return candidates[best]

    def _start_keyframe(self, image: np.ndarray, pts: np.ndarray) -> None:
        """`image` starts a keyframe with its Shi-Tomasi corners `pts` (N, 2) [px]."""
        self._prev_image, self._prev_pts, self._kf_pts, self._kf_index = image, pts, pts, self._k
        self._prev_corners = pts
