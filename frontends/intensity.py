"""Frame-only image sources: the original APS frames and their histogram equalisation."""

from __future__ import annotations

import cv2
import numpy as np

from eas_vo.plugins import Frontend
from eas_vo.types import Sample


class OriginalFrontend(Frontend):
    """The APS frame as recorded."""

    name = "original"
    description = "original APS frames, unchanged"
    needs_frames = True

    def __call__(self, sample: Sample) -> np.ndarray:
        return sample.frame


class HistEqFrontend(Frontend):
    """The APS frame after global histogram equalisation (the paper's 'enhanced' images)."""

    name = "histeq"
    description = "APS frames enhanced by histogram equalisation"
    needs_frames = True

    def __call__(self, sample: Sample) -> np.ndarray:
        return cv2.equalizeHist(sample.frame)
