"""`klt`, the paper's tracker: Shi-Tomasi corners, pyramidal Lucas-Kanade flow from frame
to frame, five-point essential matrix, thresholds 1 and 2.

It only ever sees uint8 images; the geometry is the shared `eas_vo.geometry.two_view`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from eas_vo.errors import ConfigError
from eas_vo.geometry.two_view import ESSENTIAL_METHODS, GEOMETRIES, rotation_from_correspondences
from eas_vo.plugins import Tracker
from eas_vo.types import CameraModel, FrameRecord, ImuSeries, RelativeRotation
from eas_vo.validation import check_choice, check_range


@dataclass(frozen=True)
class KltConfig:
    """Corner detection, optical flow and essential-matrix settings.

    Attributes:
        max_corners, quality_level, min_distance_px, block_size: Shi-Tomasi detection.
        lk_win_size, lk_max_level: pyramidal Lucas-Kanade window [px] and pyramid levels.
        threshold1: with fewer correspondences the previous rotation is kept.
        threshold2: with fewer correspondences corners are detected again in the frame.
        keyframe_interval: 0 (the paper) or N: also measure the rotation from a keyframe to
            each frame with the corners tracked since it, a new keyframe every N frames and
            at each redetection (multi-frame edges i -> j for the gtsam backend).
        geometry: `essential` (the paper), `rotation` or `auto` (see rotation_from_correspondences).
        essential_method: robust estimator around OpenCV's five-point solver: `usac`
            (RANSAC with local optimisation, the default), `ransac` (plain), `magsac`, `lmeds`.
        ransac_threshold_px: inlier threshold [px].
        ransac_confidence: success probability.
    """

    max_corners: int = 500
    quality_level: float = 0.01
    min_distance_px: float = 7.0
    block_size: int = 7
    lk_win_size: int = 21
    lk_max_level: int = 3
    threshold1: int = 10
    threshold2: int = 150
    keyframe_interval: int = 0
    geometry: str = "essential"
    essential_method: str = "usac"
    ransac_threshold_px: float = 1.0
    ransac_confidence: float = 0.999

    def validate(self) -> None:
        check_range(self, "max_corners", 1, 100_000)
        check_range(self, "quality_level", 0.0, 1.0, lo_open=True)
        check_range(self, "min_distance_px", 0.0, 1000.0)
        check_range(self, "block_size", 3, 99)
        check_range(self, "lk_win_size", 3, 201)
        check_range(self, "lk_max_level", 0, 10)
        check_range(self, "threshold1", 5, 100_000)
        check_range(self, "threshold2", 5, 100_000)
        check_range(self, "keyframe_interval", 0, 100_000)
        if self.threshold1 > self.threshold2:
            raise ConfigError(f"threshold1 ({self.threshold1}) must not exceed threshold2 ({self.threshold2})")
        check_choice(self, "geometry", GEOMETRIES)
        check_choice(self, "essential_method", ESSENTIAL_METHODS)
        check_range(self, "ransac_threshold_px", 0.0, 100.0, lo_open=True)
        check_range(self, "ransac_confidence", 0.0, 1.0, lo_open=True)


class KltTracker(Tracker):
    """Tracks corners frame to frame and measures the relative rotation of each pair.

    Feed frames in order with `process`; it returns what happened and the measured
    rotations: `R_{k-1}_{k}` between the previous and this frame (the paper) and, with
    `keyframe_interval` > 0, `R_{kf}_{k}` from the corners tracked since the keyframe kf.
    """

    name = "klt"
    description = "Shi-Tomasi corners, pyramidal Lucas-Kanade, five-point essential matrix (the paper)"
    Config = KltConfig

    def __init__(self, config: KltConfig | None = None, camera: CameraModel | None = None, *, imu: ImuSeries | None = None):
        super().__init__(config, camera, imu=imu)
        c = self.config
        self._lk_params = dict(
            winSize=(c.lk_win_size, c.lk_win_size),
            maxLevel=c.lk_max_level,
            criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01),
        )

    def reset(self) -> None:
        """Forget every frame seen; the next frame is a first frame."""
        self._prev_image: np.ndarray | None = None
        self._prev_pts = np.empty((0, 2), np.float32)
        self._kf_pts = np.empty((0, 2), np.float32)  # where each tracked corner was in the keyframe
        self._kf_index = 0
        self._k = -1

    def detect(self, image: np.ndarray) -> np.ndarray:
        """Shi-Tomasi corners of `image`, (N, 2) float32 [px]."""
        c = self.config
        pts = cv2.goodFeaturesToTrack(
            image, c.max_corners, c.quality_level, c.min_distance_px, blockSize=c.block_size
        )
        return np.empty((0, 2), np.float32) if pts is None else pts.reshape(-1, 2).astype(np.float32)

    def track(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """LK-track the previous corners into `image`: (N, 2) positions [px] and a mask of the tracked ones."""
        if len(self._prev_pts) == 0:
            return np.empty((0, 2), np.float32), np.zeros(0, bool)
        cur, status, _ = cv2.calcOpticalFlowPyrLK(
            self._prev_image, image, self._prev_pts.reshape(-1, 1, 2), None, **self._lk_params
        )
        h, w = image.shape
        cur = cur.reshape(-1, 2)
        ok = (status.ravel() == 1) & (cur[:, 0] >= 0) & (cur[:, 0] <= w - 1) & (cur[:, 1] >= 0) & (cur[:, 1] <= h - 1)
        return cur, ok

    def _measure(self, pts_from: np.ndarray, pts_to: np.ndarray, i: int, j: int) -> RelativeRotation | None:
        c = self.config
        result = rotation_from_correspondences(
            self.camera.undistort(pts_from),
            self.camera.undistort(pts_to),
            c.ransac_threshold_px / self.camera.focal_px,
            c.ransac_confidence,
            c.essential_method,
            c.geometry,
        )
        return None if result is None else RelativeRotation(i, j, result[0], result[1])

    def process(self, image: np.ndarray, t: float) -> tuple[FrameRecord, list[RelativeRotation]]:
        """Track into `image` (uint8, sensor size) taken at `t` [s]."""
        c = self.config
        self._k += 1
        k = self._k
        if self._prev_image is None:
            self._start_keyframe(image, self.detect(image))
            self._prev_t = t
            return FrameRecord(k, t, 0, 0, "first", True), []
        if t <= self._prev_t:  # no time between the two: nothing to measure, the rotation is kept
            return FrameRecord(k, t, 0, 0, "same_time", False), []
        self._prev_t = t

        cur, ok = self.track(image)
        nc = int(ok.sum())
        edges, inliers, status = [], 0, "few_correspondences"
        if nc >= c.threshold1:
            step = self._measure(self._prev_pts[ok], cur[ok], k - 1, k)
            if step is None:
                status = "no_model"
            else:
                edges.append(step)
                inliers, status = step.inliers, "ok"
                if c.keyframe_interval > 0 and k - self._kf_index >= 2:
                    skip = self._measure(self._kf_pts[ok], cur[ok], self._kf_index, k)
                    if skip is not None:
                        edges.append(skip)

        redetect = nc < c.threshold2
        if redetect:
            self._start_keyframe(image, self.detect(image))
        else:
            self._prev_image, self._prev_pts, self._kf_pts = image, cur[ok], self._kf_pts[ok]
            if c.keyframe_interval > 0 and k - self._kf_index >= c.keyframe_interval:
                self._kf_index, self._kf_pts = k, cur[ok]
        return FrameRecord(k, t, nc, inliers, status, redetect), edges

    def _start_keyframe(self, image: np.ndarray, pts: np.ndarray) -> None:
        self._prev_image, self._prev_pts, self._kf_pts, self._kf_index = image, pts, pts, self._k
