"""ORB statistics of an image sequence, as the paper's Table 2: keypoints per image and
matches between adjacent images (brute-force Hamming matching with cross-check)."""

from __future__ import annotations

import cv2
import numpy as np


class OrbStats:
    """Feed images in order; `summary()` gives the averages."""

    def __init__(self, features: int = 1000):
        self.orb = cv2.ORB_create(nfeatures=features)
        self.matcher = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)
        self.keypoints: list[int] = []
        self.matches: list[int] = []
        self._previous = None

    def add(self, image: np.ndarray) -> None:
        keypoints, descriptors = self.orb.detectAndCompute(image, None)
        self.keypoints.append(len(keypoints))
        if self._previous is not None:
            if descriptors is None or self._previous is None or len(self._previous) == 0:
                self.matches.append(0)
            else:
                self.matches.append(len(self.matcher.match(self._previous, descriptors)))
        self._previous = descriptors if descriptors is not None else np.empty((0, 32), np.uint8)

    def summary(self) -> dict:
        return {
            "orb_keypoints_mean": float(np.mean(self.keypoints)) if self.keypoints else 0.0,
            "orb_matches_mean": float(np.mean(self.matches)) if self.matches else 0.0,
        }
