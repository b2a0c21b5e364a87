"""A third-party frontend: Canny edges of the histogram-equalised frame."""

from dataclasses import dataclass

import cv2

from eas_vo.plugins import Frontend


@dataclass(frozen=True)
class EdgesConfig:
    low: int = 50
    high: int = 150


class EdgesFrontend(Frontend):
    name = "edges"
    description = "Canny edges of the equalised frame (an example plugin)"
    Config = EdgesConfig
    needs_frames = True

    def __call__(self, sample):
        frame = cv2.equalizeHist(sample.frame)
        return cv2.GaussianBlur(cv2.Canny(frame, self.config.low, self.config.high), (5, 5), 1.0)
