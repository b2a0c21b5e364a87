"""Extents in pixels follow the camera's focal length (PixelScale)."""

import numpy as np
import pytest

from eas_vo.trackers.klt import KltConfig, KltTracker
from eas_vo.trackers.measurement import REFERENCE_FOCAL_PX, PixelScale
from eas_vo.types import CameraModel


def camera_of_focal(focal_px: float) -> CameraModel:
    return CameraModel(640, 480, np.array([[focal_px, 0, 320], [0, focal_px, 240], [0, 0, 1]]))


@pytest.mark.parametrize("focal_px, levels, window, min_distance, block", [
    (200.0, 3, 21, 7.0, 7),    # the reference: as stated
    (198.96, 3, 21, 6.9636, 7),  # the ECD DAVIS240C: the same windows and pyramid
    (400.0, 4, 21, 14.0, 14),  # one octave: one level more of the same window
    (288.0, 3, 30, 10.08, 10),  # DAVIS346-like: less than an octave, the window takes it
    (1066.7, 5, 28, 37.3345, 37),  # 1280x720: two whole octaves, the window the rest (x1.33)
    (100.0, 2, 21, 3.5, 4),    # half the reference: a level less
])
def test_extents_follow_the_focal_length(focal_px, levels, window, min_distance, block):
    config = PixelScale.of(camera_of_focal(focal_px)).config(KltConfig())
    assert (config.lk_max_level, config.lk_win_size, config.block_size) == (levels, window, block)
    assert config.min_distance_px == pytest.approx(min_distance, abs=1e-3)
    # precisions stay the sensor's pixels
    reference = KltConfig()
    assert (config.ransac_threshold_px, config.max_residual_px, config.lk_epsilon_px, config.fb_max_px) == (
        reference.ransac_threshold_px, reference.max_residual_px, reference.lk_epsilon_px, reference.fb_max_px)


def test_the_tracker_works_with_the_converted_extents():
    tracker = KltTracker(KltConfig(lk_max_level=2), camera_of_focal(2 * REFERENCE_FOCAL_PX))
    assert (tracker.config.lk_max_level, tracker.config.lk_win_size, tracker.config.min_distance_px) == (3, 21, 14.0)
    assert KltTracker(KltConfig(), None).config == KltConfig()
