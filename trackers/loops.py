"""Loop closure and relocalisation, for any tracker: keyframes (their keypoints, descriptors
and corners detected only once a query needs them), recognised again when the running
estimate says the camera looks the same way (or after the track was lost), verified with
rotation-only RANSAC on the matched keypoints, refined by LK from the keyframe's corners
(measured with `loop_geometry`), added as edges kf -> k. Not a plugin."""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.geometry.rotations import geodesic_angle
from eas_vo.trackers.features import DETECTORS, Features, RefinedMatching
from eas_vo.trackers.measurement import PixelScale, TwoViewConfig
from eas_vo.types import RelativeRotation
from eas_vo.validation import check_choice, check_range

LOOP_GEOMETRIES = ("rotation", "homography")


@dataclass(frozen=True)
class LoopClosureConfig:
    """Attributes:
    loop_closure: off (the paper) or on.
    loop_detector: keypoints for keyframes (`orb` or `sift`); the loop rotation they give
        is refined by LK from the keyframe's corners, so ORB's coarser keypoints suffice.
    loop_keyframe_deg: a new keyframe when the view turned this much [deg] since the last.
    loop_min_gap: a frame may close a loop only with keyframes at least this many frames old.
    loop_overlap_deg: candidates are keyframes whose optical axis is within this angle [deg]
        of the current one by the running estimate (about half the DAVIS240's field of view).
    loop_every: query for loops at most every this many frames, and only once the view
        turned `loop_keyframe_deg` (along its path) since the last query: a still camera
        would find the loop it just closed again. After a lost frame, at once.
    loop_min_inliers: a loop is accepted with at least this many rotation-only inliers
        (and not weak): twice the support a frame-to-frame edge needs, since a wrong loop
        costs more than a missed one.
    loop_geometry: the geometry of the LK refinement: `rotation`, or `homography`, which
        keeps the parallax of the camera's translation out of the rotation where the
        homography determines it (else the loop is measured rotation-only). A loop spans
        seconds in which a hand-held camera moves by centimetres, whose parallax a
        rotation-only loop takes for rotation: an error the size of the chain's it should
        correct (docs/best_config.md, "Loops and the hand's translation").
    """

    loop_closure: bool = False
    loop_detector: str = "orb"
    loop_keyframe_deg: float = 5.0
    loop_min_gap: int = 20
    loop_overlap_deg: float = 30.0
    loop_every: int = 5
    loop_min_inliers: int = 30
    loop_geometry: str = "rotation"

    def validate(self) -> None:
        check_choice(self, "loop_detector", DETECTORS)
        check_range(self, "loop_keyframe_deg", 0.0, 180.0, lo_open=True)
        check_range(self, "loop_min_gap", 2, 10**6)
        check_range(self, "loop_overlap_deg", 0.0, 180.0, lo_open=True)
        check_range(self, "loop_every", 1, 10**6)
        check_range(self, "loop_min_inliers", 5, 10**6)
        check_choice(self, "loop_geometry", LOOP_GEOMETRIES)


@dataclass
class _Keyframe:
    index: int
    R_w_c: np.ndarray
    image: np.ndarray
    corners: np.ndarray | None = None  # Shi-Tomasi corners [px] for the LK refinement, once needed
    detected: tuple | None = None  # keypoints [px] and their descriptors, once needed


class LoopCloser:
    """Feed every frame in order with `step`; it keeps a dead-reckoned R_w_c from the frame's
    consecutive edge and returns the loop edges it verified for this frame."""

    def __init__(self, config: LoopClosureConfig, camera: CameraModel):
        self.config, self.camera = config, camera
        self.features = Features(config.loop_detector)
        self._min_distance_px, self._block_size = PixelScale.of(camera).corners(7.0, 7)
        fine = TwoViewConfig(
            geometry=config.loop_geometry,
            min_inliers=config.loop_min_inliers,
            covariance=getattr(config, "covariance", TwoViewConfig.covariance),  # the tracker's method
        )
        self.matching = RefinedMatching(self.features, camera, fine, config.loop_min_inliers)
        self.keyframes: list[_Keyframe] = []
        self._axes = np.empty((0, 3))  # each keyframe's optical axis in the world frame
        self.R_w_c = np.eye(3)
        self._since_query = 0
        self._turned_deg = 0.0  # how far the view turned since the last query [deg], along its path

    def step(self, k: int, image: np.ndarray, edges: list[RelativeRotation], lost: bool) -> list[RelativeRotation]:
        c = self.config
        step = next((e for e in edges if e.j == k and e.i == k - 1), None)
        if step is not None:
            self.R_w_c = self.R_w_c @ step.R_i_j
            self._turned_deg += np.degrees(geodesic_angle(np.eye(3), step.R_i_j))
        self._since_query += 1
        new_keyframe = (
            not self.keyframes or np.degrees(geodesic_angle(self.keyframes[-1].R_w_c, self.R_w_c)) > c.loop_keyframe_deg
        )
        candidates = self._candidates(k, lost)
        query = len(candidates) > 0 and (
            lost or (self._since_query >= c.loop_every and self._turned_deg > c.loop_keyframe_deg)
        )
        if not (query or new_keyframe):
            return []
        current, loops = _Keyframe(k, self.R_w_c, image), []
        if query:
            self._since_query, self._turned_deg = 0, 0.0
            closest = self.keyframes[candidates[0]]
            edge, _ = self.matching.rotation(
                closest.image,
                self._corners(closest),
                self._detected(closest),
                image,
                self._detected(current),
                closest.index,
                k,
            )
            if edge is not None:
                loops = [replace(edge, loop=True)]
                self.R_w_c = closest.R_w_c @ edge.R_i_j  # relocalise the running estimate on the loop
        if new_keyframe:
            current.R_w_c = self.R_w_c.copy()
            self.keyframes.append(current)
            self._axes = np.vstack([self._axes, self.R_w_c[:, 2]])
        return loops

    def _detected(self, keyframe: _Keyframe) -> tuple:
        """The keyframe's keypoints and descriptors, detected the first time they are needed."""
        if keyframe.detected is None:
            keyframe.detected = self.features.detect(keyframe.image)
        return keyframe.detected

    def _corners(self, keyframe: _Keyframe) -> np.ndarray:
        """The keyframe's Shi-Tomasi corners [px], detected the first time they are needed."""
        if keyframe.corners is None:
            corners = cv2.goodFeaturesToTrack(
                keyframe.image, 300, 0.01, self._min_distance_px, blockSize=self._block_size
            )
            keyframe.corners = np.empty((0, 2), np.float32) if corners is None else corners.reshape(-1, 2)
        return keyframe.corners

    def _candidates(self, k: int, lost: bool) -> np.ndarray:
        """Indices into `keyframes` of those old enough to close a loop with frame k and looking
        within `loop_overlap_deg` of its optical axis (any, after a lost frame), the closest first."""
        c = self.config
        old = np.flatnonzero(k - np.array([kf.index for kf in self.keyframes], int) >= c.loop_min_gap)
        angles = np.arccos(np.clip(self._axes[old] @ self.R_w_c[:, 2], -1.0, 1.0))
        keep = np.ones(len(old), bool) if lost else np.degrees(angles) < c.loop_overlap_deg
        return old[keep][np.argsort(angles[keep], kind="stable")]
