"""`match`: rotation-invariant keypoints and descriptors matched frame to frame, the rotation
from the shared two-view geometry. Follows motion of any speed as long as consecutive images
overlap: nothing is predicted, so nothing can be lost by a wrong prediction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.plugins import Tracker
from eas_vo.trackers.features import DETECTORS, MATCHINGS, MAX_RESIDUAL_PX, MIN_MATCHES, RANSAC_THRESHOLD_PX, Features
from eas_vo.trackers.loops import LoopCloser, LoopClosureConfig
from eas_vo.trackers.measurement import StepBound, TwoViewConfig, frame_record, status
from eas_vo.types import FrameRecord, RelativeRotation
from eas_vo.validation import check_choice, check_range


@dataclass(frozen=True)
class MatchConfig(LoopClosureConfig, TwoViewConfig):
    """Keypoints, descriptors and matching, (TwoViewConfig) the geometry and
    (LoopClosureConfig) loop closure.

    Attributes:
        detector: `orb` or `sift`.
        max_features: keypoints per image at most.
        matching: `ratio` (Lowe's test) or `crosscheck` (mutual nearest neighbours).
        ratio: Lowe's ratio (nearest / second-nearest descriptor distance).
        min_matches: with fewer matches, or a model with fewer inliers, nothing is measured
            (the frame is `lost`): a rotation so few matches support is noise (docs/method.md,
            "Another tracker: `match`").
        geometry: as TwoViewConfig; `auto` by default here (GRIC picks rotation-only or the
            essential matrix per pair).
        ransac_threshold_px, max_residual_px: twice TwoViewConfig's (see features.RANSAC_THRESHOLD_PX).
    """

    geometry: str = "auto"
    ransac_threshold_px: float = RANSAC_THRESHOLD_PX
    max_residual_px: float = MAX_RESIDUAL_PX
    detector: str = "orb"
    max_features: int = 1000
    matching: str = "ratio"
    ratio: float = 0.8
    min_matches: int = MIN_MATCHES

    def validate(self) -> None:
        TwoViewConfig.validate(self)
        LoopClosureConfig.validate(self)
        check_choice(self, "detector", DETECTORS)
        check_range(self, "max_features", 10, 100_000)
        check_choice(self, "matching", MATCHINGS)
        check_range(self, "ratio", 0.0, 1.0, lo_open=True)
        check_range(self, "min_matches", 5, 100_000)


class MatchTracker(Tracker):
    """Matches the keypoints of each image with the previous image's and measures R_{k-1}_{k}."""

    name = "match"
    description = "ORB or SIFT descriptors matched frame to frame (ratio or cross check), shared two-view geometry"
    Config = MatchConfig

    @property
    def closes_loops(self) -> bool:
        return self.config.loop_closure

    def reset(self) -> None:
        c = self.config
        self.features = Features(c.detector, c.max_features, c.matching, c.ratio)
        self._previous: tuple[np.ndarray, np.ndarray | None] | None = None  # keypoints [px], descriptors
        self._prev_t = -np.inf
        self._k = -1
        self._loops = LoopCloser(c, self.camera) if c.loop_closure else None
        self._bound = StepBound(c, self.camera)

    def process(self, image: np.ndarray, t: float) -> tuple[FrameRecord, list[RelativeRotation]]:
        c = self.config
        self._k += 1
        k = self._k
        if self._previous is not None and t <= self._prev_t:
            return FrameRecord(k, t, 0, 0, "same_time", False), []
        detected = self.features.detect(image)
        previous, t_prev = self._previous, self._prev_t
        self._previous, self._prev_t = detected, t
        if previous is None:
            record, edges = FrameRecord(k, t, 0, 0, "first", True), []
        else:
            step, nc = self.features.rotation(c, self.camera, previous, detected, k - 1, k, c.min_matches)
            record, edges = (
                frame_record(c, self.camera, k, t, nc, step, True, nc >= c.min_matches),
                [step] if step else [],
            )
            record, edges = self._bound.judge(record, edges, t_prev, t)
            record = status(c, record, edges[0] if edges else None, self.camera.focal_px)  # the label reported
        if self._loops is not None:
            edges = edges + self._loops.step(k, image, edges, lost=record.status == "lost")
        return record, edges
