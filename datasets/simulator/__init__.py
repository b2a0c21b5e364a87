"""Synthetic dim-scene DAVIS simulator: a textured 3-D room with high-dynamic-range
lighting, hand-held motion, APS frames, ESIM-style events, ground truth and IMU."""

from eas_vo.datasets.simulator.generate import SimConfig, simulate

__all__ = ["SimConfig", "simulate"]
