"""A third-party tracker that reads events: pan and tilt from the median optical flow between
the event images of consecutive samples (small angles, no roll: a sketch, not cmax)."""

from dataclasses import dataclass

import cv2
import numpy as np

from eas_vo.plugins import Tracker
from eas_vo.types import FrameRecord, RelativeRotation


@dataclass(frozen=True)
class EventFlowConfig:
    blur_px: float = 1.5
    min_events: int = 1000


class EventFlowTracker(Tracker):
    name = "evflow"
    description = "pan and tilt from the flow between consecutive event images (an example plugin)"
    Config = EventFlowConfig
    needs_events = True  # process() gets sample=
    reads_images = False  # image is None: no frontend runs

    def reset(self):
        self.previous = None  # the last sample's event image
        self.k = -1

    def process(self, image, t, *, sample):
        self.k += 1
        events = sample.events_since_previous
        width, height = self.camera.width, self.camera.height
        counts = np.bincount(events["y"].astype(np.int64) * width + events["x"], minlength=width * height)
        counts = np.minimum(counts, 2).reshape(height, width).astype(np.uint8)  # a hot pixel counts as 2
        current = cv2.GaussianBlur(counts * 127, (0, 0), self.config.blur_px)
        previous, self.previous = self.previous, current
        if previous is None:
            return FrameRecord(self.k, t, 0, 0, "first", False, events=len(events)), []
        if len(events) < self.config.min_events:
            return FrameRecord(self.k, t, 0, 0, "lost", False, reason="too few events", events=len(events)), []
        flow = cv2.calcOpticalFlowFarneback(previous, current, None, 0.5, 4, 21, 3, 5, 1.1, 0)
        dx, dy = np.median(flow.reshape(-1, 2), axis=0)  # the scene's shift [px]
        turn = np.array([dy, -dx, 0.0]) / self.camera.focal_px  # the camera's [rad]
        edge = RelativeRotation(self.k - 1, self.k, cv2.Rodrigues(turn)[0], inliers=len(events))
        return FrameRecord(self.k, t, 0, len(events), "ok", False, events=len(events)), [edge]
