"""Loop closure and relocalisation, for any tracker: keyframes with descriptors and corners,
recognised again when the running estimate says the camera looks the same way (or after the
track was lost), verified with rotation-only RANSAC on the matched keypoints, refined by LK
from the keyframe's corners, added as edges kf -> k. Not a plugin."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from eas_vo.geometry.rotations import geodesic_angle
from eas_vo.trackers.features import DETECTORS, MAX_RESIDUAL_PX, RANSAC_THRESHOLD_PX, Features
from eas_vo.trackers.measurement import TwoViewConfig, measure, weakness
from eas_vo.trackers.motion import lk_params, lk_track
from eas_vo.types import CameraModel, RelativeRotation
from eas_vo.validation import check_choice, check_range


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
        loop_every: query for loops every this many frames (every frame after a lost one).
        loop_min_inliers: a loop is accepted with at least this many rotation-only inliers
            (and not weak): twice the support a frame-to-frame edge needs, since a wrong loop
            costs more than a missed one.
    """

    loop_closure: bool = False
    loop_detector: str = "orb"
    loop_keyframe_deg: float = 5.0
    loop_min_gap: int = 20
    loop_overlap_deg: float = 30.0
    loop_every: int = 5
    loop_min_inliers: int = 30

    def validate(self) -> None:
        check_choice(self, "loop_detector", DETECTORS)
        check_range(self, "loop_keyframe_deg", 0.0, 180.0, lo_open=True)
        check_range(self, "loop_min_gap", 2, 10**6)
        check_range(self, "loop_overlap_deg", 0.0, 180.0, lo_open=True)
        check_range(self, "loop_every", 1, 10**6)
        check_range(self, "loop_min_inliers", 5, 10**6)


@dataclass
class _Keyframe:
    index: int
    R_w_c: np.ndarray
    image: np.ndarray
    corners: np.ndarray  # Shi-Tomasi corners [px], for the LK refinement
    detected: tuple  # keypoints [px] and their descriptors


class LoopCloser:
    """Feed every frame in order with `step`; it keeps a dead-reckoned R_w_c from the frame's
    consecutive edge and returns the loop edges it verified for this frame."""

    def __init__(self, config: LoopClosureConfig, camera: CameraModel):
        self.config, self.camera = config, camera
        self.features = Features(config.loop_detector)
        self.coarse = TwoViewConfig(geometry="rotation", ransac_threshold_px=RANSAC_THRESHOLD_PX,
                                    max_residual_px=MAX_RESIDUAL_PX, min_inliers=config.loop_min_inliers)
        self.fine = TwoViewConfig(geometry="rotation", min_inliers=config.loop_min_inliers)
        self.lk = lk_params()
        self.keyframes: list[_Keyframe] = []
        self.R_w_c = np.eye(3)
        self._since_query = 0

    def step(self, k: int, image: np.ndarray, edges: list[RelativeRotation], lost: bool) -> list[RelativeRotation]:
        c = self.config
        step = next((e for e in edges if e.j == k and e.i == k - 1), None)
        if step is not None:
            self.R_w_c = self.R_w_c @ step.R_i_j
        self._since_query += 1
        candidates = [kf for kf in self.keyframes if k - kf.index >= c.loop_min_gap
                      and (lost or np.degrees(_axis_angle(kf.R_w_c, self.R_w_c)) < c.loop_overlap_deg)]
        new_keyframe = not self.keyframes or np.degrees(geodesic_angle(self.keyframes[-1].R_w_c, self.R_w_c)) > c.loop_keyframe_deg
        query = candidates and (lost or self._since_query >= c.loop_every)
        if not (query or new_keyframe):
            return []
        detected = self.features.detect(image)
        loops = []
        if query:
            self._since_query = 0
            closest = min(candidates, key=lambda kf: _axis_angle(kf.R_w_c, self.R_w_c))  # overlaps most
            edge = self._verify(closest, k, image, detected)
            if edge is not None:
                loops = [edge]
                self.R_w_c = closest.R_w_c @ edge.R_i_j  # relocalise the running estimate on the loop
        if new_keyframe:
            corners = cv2.goodFeaturesToTrack(image, 300, 0.01, 7.0, blockSize=7)
            corners = np.empty((0, 2), np.float32) if corners is None else corners.reshape(-1, 2)
            self.keyframes.append(_Keyframe(k, self.R_w_c.copy(), image, corners, detected))
        return loops

    def _verify(self, kf: _Keyframe, k: int, image: np.ndarray, detected: tuple) -> RelativeRotation | None:
        """The loop kf -> k: matched keypoints give it, LK from the keyframe's corners refines it."""
        coarse, _ = self.features.rotation(self.coarse, self.camera, kf.detected, detected, kf.index, k,
                                           self.config.loop_min_inliers)
        if coarse is None or weakness(self.coarse, coarse, self.camera.focal_px):
            return None
        cur, ok = lk_track(self.camera, kf.image, kf.corners, image, self.lk, coarse.R_i_j, fb_max_px=1.0)
        fine = measure(self.fine, self.camera, kf.corners[ok], cur[ok], kf.index, k) if ok.sum() >= self.config.loop_min_inliers else None
        if fine is None or weakness(self.fine, fine, self.camera.focal_px):
            return coarse
        return fine


def _axis_angle(R_w_a: np.ndarray, R_w_b: np.ndarray) -> float:
    """Angle [rad] between the optical axes (camera z) of two orientations."""
    return float(np.arccos(np.clip(R_w_a[:, 2] @ R_w_b[:, 2], -1.0, 1.0)))
