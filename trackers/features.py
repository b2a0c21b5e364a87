"""Rotation-invariant keypoints and descriptors (OpenCV) and their matching, shared by the
trackers that match rather than track. Not a plugin."""

from __future__ import annotations

import cv2
import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.trackers.measurement import PixelScale, TwoViewConfig, measure, weakness
from eas_vo.trackers.motion import lk_params, lk_track
from eas_vo.types import RelativeRotation

DETECTORS = ("orb", "sift")  # AKAZE left OpenCV's main modules in 5.0
MATCHINGS = ("ratio", "crosscheck")

#: Measuring from matched keypoints: they are localised on an image pyramid (ORB: scale 1.2
#: per level) to about half a pixel or worse at the base level, unlike LK's sub-pixel tracks,
#: so the inlier threshold and the residual above which a fit is weak are twice LK's [px]
#: (the residual: twice the 0.5 px LK's was when the fallback was developed).
RANSAC_THRESHOLD_PX = 2.0
MAX_RESIDUAL_PX = 1.0
#: The inlier ratio below which a coarse (matched) rotation is no measurement: the value the
#: fallback was developed with (the status's calibration covers LK's measurements only).
COARSE_MIN_INLIER_RATIO = 0.5
#: With fewer matches nothing is measured.
MIN_MATCHES = 10


class Features:
    """Detects keypoints with descriptors in an image and matches two sets of them.

    Args:
        detector: `orb` or `sift` (both rotation invariant).
        max_features: at most this many keypoints per image.
        matching: `ratio` (Lowe's test: nearest / second nearest distance below `ratio`) or
            `crosscheck` (mutual nearest neighbours).
        ratio: Lowe's ratio.
    """

    def __init__(self, detector: str = "orb", max_features: int = 1000, matching: str = "ratio", ratio: float = 0.8):
        if detector == "orb":
            self.extractor = cv2.ORB_create(nfeatures=max_features)
        else:
            self.extractor = cv2.SIFT_create(nfeatures=max_features)
        norm = cv2.NORM_L2 if detector == "sift" else cv2.NORM_HAMMING
        self.matcher = cv2.BFMatcher(norm, crossCheck=matching == "crosscheck")
        self.matching, self.ratio = matching, ratio

    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(N, 2) keypoint positions [px] and their descriptors (None when there are none)."""
        keypoints, descriptors = self.extractor.detectAndCompute(image, None)
        return np.float32([kp.pt for kp in keypoints]).reshape(-1, 2), descriptors

    def match(
        self, descriptors_a: np.ndarray | None, descriptors_b: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Indices (into a, into b) of the accepted matches, one per keypoint of a at most."""
        if descriptors_a is None or descriptors_b is None or len(descriptors_a) == 0 or len(descriptors_b) < 2:
            return np.empty(0, int), np.empty(0, int)
        if self.matching == "crosscheck":
            pairs = [(m.queryIdx, m.trainIdx) for m in self.matcher.match(descriptors_a, descriptors_b)]
        else:
            pairs = [
                (m[0].queryIdx, m[0].trainIdx)
                for m in self.matcher.knnMatch(descriptors_a, descriptors_b, k=2)
                if len(m) == 2 and m[0].distance < self.ratio * m[1].distance
            ]
        if not pairs:
            return np.empty(0, int), np.empty(0, int)
        a, b = np.array(pairs).T
        return a, b

    def rotation(
        self,
        config: TwoViewConfig,
        camera: CameraModel,
        detected_i: tuple,
        detected_j: tuple,
        i: int,
        j: int,
        min_matches: int = MIN_MATCHES,
    ) -> tuple[RelativeRotation | None, int]:
        """R_i_j from two detections (keypoints [px], descriptors) by their matches, and the
        number of matches. None with fewer than `min_matches` matches, or a model with fewer
        inliers (a rotation so few matches support is noise)."""
        a, b = self.match(detected_i[1], detected_j[1])
        if len(a) < min_matches:
            return None, len(a)
        edge = measure(config, camera, detected_i[0][a], detected_j[0][b], i, j)
        return (edge if edge is not None and edge.inliers >= min_matches else None), len(a)


class RefinedMatching:
    """The rotation between two views from matched keypoints, refined by LK: the matches give
    a coarse rotation (keypoints localised to about half a pixel), LK started from it tracks
    the first view's corners into the second (forward-backward within 1 px) and, unless that
    measurement is weak, replaces it. A weak coarse rotation is no measurement.

    Args:
        features: the keypoint detector and matcher.
        fine: the geometry of the LK refinement (the coarse one: rotation-only with the fixed
            RANSAC_THRESHOLD_PX, MAX_RESIDUAL_PX and COARSE_MIN_INLIER_RATIO). LK's pyramid
            is OpenCV's default (3 levels of 21 px) converted to the camera
            (measurement.PixelScale).
        min_inliers: fewer matches, or inliers, and nothing is measured.
    """

    def __init__(self, features: Features, camera: CameraModel, fine: TwoViewConfig, min_inliers: int = MIN_MATCHES):
        self.features, self.camera, self.fine, self.min_inliers = features, camera, fine, min_inliers
        self.coarse = TwoViewConfig(
            geometry="rotation",
            ransac_threshold_px=RANSAC_THRESHOLD_PX,
            max_residual_px=MAX_RESIDUAL_PX,
            min_inliers=min_inliers,
            min_inlier_ratio=COARSE_MIN_INLIER_RATIO,
            covariance=fine.covariance,
        )
        levels, window = PixelScale.of(camera).pyramid(3, 21)
        self.lk = lk_params(window, levels)

    def rotation(
        self,
        source: np.ndarray,
        corners: np.ndarray,
        source_detected: tuple,
        image: np.ndarray,
        detected: tuple,
        i: int,
        j: int,
    ) -> tuple[RelativeRotation | None, int]:
        """R_i_j from `source` (its Shi-Tomasi `corners` [px] and `source_detected` keypoints)
        to `image` (`detected`), and the number of matches."""
        coarse, n_matches = self.features.rotation(
            self.coarse, self.camera, source_detected, detected, i, j, self.min_inliers
        )
        if coarse is None or weakness(self.coarse, coarse, self.camera.focal_px):
            return None, n_matches
        cur, ok = lk_track(self.camera, source, corners, image, self.lk, coarse.R_i_j, fb_max_px=1.0)
        fine = measure(self.fine, self.camera, corners[ok], cur[ok], i, j) if ok.sum() >= self.min_inliers else None
        if fine is None or weakness(self.fine, fine, self.camera.focal_px):
            return coarse, n_matches
        return fine, n_matches
