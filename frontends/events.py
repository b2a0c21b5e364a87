"""Event slice (the paper's Eq. 1) and EAS, its fusion with the frame (Eq. 2 / Algorithm 1)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from eas_vo.plugins import Frontend
from eas_vo.types import Sample
from eas_vo.validation import check_range


def event_slice(events: np.ndarray, n: int, width: int, height: int) -> np.ndarray:
    """Eq. 1: binary slice of the first `n` events (polarity ignored).

    Args:
        events: EVENT_DTYPE array starting at the slice's first event.
        n: number of events aggregated (fewer if fewer remain).
        width, height: sensor size [px].

    Returns:
        (height, width) uint8, 1 where any of the events fell, else 0.
    """
    chunk = events[:n]
    es = np.zeros((height, width), dtype=np.uint8)
    es[chunk["y"], chunk["x"]] = 1
    return es


def gaussian_kernel_size(sigma_px: float) -> int:
    """Odd kernel size covering +-3 sigma."""
    return 2 * math.ceil(3.0 * sigma_px) + 1


def eas_fuse(frame: np.ndarray, es: np.ndarray, sigma_px: float, beta: float, gamma: float) -> np.ndarray:
    """Eq. 2 / Algorithm 1: superimpose the smoothed event slice on the frame where it is dark.

    EAS = I + alpha * G(es) where I < beta, else I; alpha = max(max(I), gamma).

    Args:
        frame: (H, W) uint8 intensity image I.
        es: (H, W) binary event slice (0/1).
        sigma_px: standard deviation of the Gaussian filter G [px].
        beta: only pixels with I < beta are enhanced [grey level].
        gamma: lower bound of the weight alpha [grey level].

    Returns:
        (H, W) uint8 fusion, saturated at 255.
    """
    k = gaussian_kernel_size(sigma_px)
    smoothed = cv2.GaussianBlur(es.astype(np.float32), (k, k), sigma_px, borderType=cv2.BORDER_REFLECT_101)
    alpha = max(float(frame.max()), gamma)
    intensity = frame.astype(np.float32)
    fused = np.where(intensity < beta, intensity + alpha * smoothed, intensity)
    return np.clip(np.rint(fused), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class SliceConfig:
    """n: events aggregated per slice (from the frame's timestamp on)."""

    n: int = 4000

    def validate(self) -> None:
        check_range(self, "n", 1, 10**9)


@dataclass(frozen=True)
class EasConfig:
    """n: events per slice; sigma_px: Gaussian std [px]; beta: enhance where I < beta;
    gamma: lower bound of alpha (grey levels)."""

    n: int = 4000
    sigma_px: float = 1.0
    beta: float = 60.0
    gamma: float = 100.0

    def validate(self) -> None:
        check_range(self, "n", 1, 10**9)
        check_range(self, "sigma_px", 0.0, 50.0, lo_open=True)
        check_range(self, "beta", 0.0, 256.0)
        check_range(self, "gamma", 0.0, 255.0)


class SliceFrontend(Frontend):
    """Binary event slice of the N events after the sample time, shown as 0/255."""

    name = "slice"
    description = "event slice: the N events after the frame, binary, polarity ignored (Eq. 1)"
    Config = SliceConfig
    needs_events = True

    def __call__(self, sample: Sample) -> np.ndarray:
        es = event_slice(sample.events_after, self.config.n, self.camera.width, self.camera.height)
        return es * np.uint8(255)


class EasFrontend(Frontend):
    """Events Aggregation and Superimposition: the frame plus its smoothed event slice."""

    name = "eas"
    description = "EAS: frame + alpha * Gaussian(event slice) where the frame is darker than beta (Eq. 2)"
    Config = EasConfig
    needs_frames = True
    needs_events = True

    def __call__(self, sample: Sample) -> np.ndarray:
        c = self.config
        es = event_slice(sample.events_after, c.n, self.camera.width, self.camera.height)
        return eas_fuse(sample.frame, es, c.sigma_px, c.beta, c.gamma)
