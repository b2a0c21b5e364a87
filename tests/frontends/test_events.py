"""Known-answer tests of Eq. 1 (event slice) and Eq. 2 (EAS), and the frame frontends."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from eas_vo.camera import CameraModel
from eas_vo.frontends.events import EasConfig, EasFrontend, SliceFrontend, eas_fuse, event_slice
from eas_vo.frontends.intensity import HistEqFrontend, OriginalFrontend
from eas_vo.types import EVENT_DTYPE, Sample


def make_events(rows):
    ev = np.zeros(len(rows), EVENT_DTYPE)
    for k, (t, x, y, p) in enumerate(rows):
        ev[k] = (t, x, y, p)
    return ev


EVENTS = make_events([(0.0, 1, 0, 1), (0.1, 2, 2, 0), (0.2, 1, 0, 0), (0.3, 3, 1, 1), (0.4, 0, 2, 1)])


def test_event_slice_is_binary_and_ignores_polarity():
    es = event_slice(EVENTS, n=5, width=4, height=3)
    expected = np.array([[0, 1, 0, 0], [0, 0, 0, 1], [1, 0, 1, 0]], np.uint8)
    np.testing.assert_array_equal(es, expected)  # pixel (1, 0) fired twice, both polarities: still 1


def test_event_slice_takes_exactly_the_first_n_events():
    es = event_slice(EVENTS, n=2, width=4, height=3)
    expected = np.zeros((3, 4), np.uint8)
    expected[0, 1] = expected[2, 2] = 1
    np.testing.assert_array_equal(es, expected)


def test_event_slice_with_fewer_events_than_n_uses_all():
    np.testing.assert_array_equal(event_slice(EVENTS, 100, 4, 3), event_slice(EVENTS, 5, 4, 3))
    assert event_slice(EVENTS[:0], 10, 4, 3).sum() == 0


def test_eas_by_hand_on_a_tiny_image():
    # One event pixel; sigma so small that the Gaussian is a delta (weight of neighbours ~ 0).
    frame = np.array([[10, 20, 30], [40, 250, 60], [70, 80, 90]], np.uint8)
    es = np.zeros((3, 3), np.uint8)
    es[0, 0] = es[1, 1] = 1
    out = eas_fuse(frame, es, sigma_px=0.05, beta=100, gamma=30)
    alpha = 250  # max(max(I), gamma)
    expected = frame.astype(int)
    expected[0, 0] = min(255, 10 + alpha)  # below beta: enhanced and saturated
    # (1, 1) = 250 >= beta: untouched although an event fell there
    np.testing.assert_array_equal(out, expected)


def test_eas_alpha_has_lower_bound_gamma():
    frame = np.full((5, 5), 4, np.uint8)
    es = np.zeros((5, 5), np.uint8)
    es[2, 2] = 1
    out = eas_fuse(frame, es, sigma_px=0.05, beta=60, gamma=100)
    assert out[2, 2] == 4 + 100  # alpha = max(4, 100)
    assert (np.delete(out.ravel(), 12) == 4).all()


def test_eas_matches_an_independent_gaussian():
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 120, (30, 40)).astype(np.uint8)
    es = (rng.random((30, 40)) < 0.1).astype(np.uint8)
    sigma, beta, gamma = 1.0, 60.0, 90.0
    out = eas_fuse(frame, es, sigma, beta, gamma)
    smoothed = gaussian_filter(es.astype(float), sigma, mode="mirror", truncate=3.0)
    alpha = max(frame.max(), gamma)
    expected = np.where(frame < beta, frame + alpha * smoothed, frame)
    np.testing.assert_allclose(out, np.clip(np.rint(expected), 0, 255), atol=1)
    assert (out[frame >= beta] == frame[frame >= beta]).all()


def _sample(frame, events):
    return Sample(index=0, t=0.0, frame=frame, events=events, event_index=0, prev_event_index=0)


def test_frontends_return_uint8_sensor_images():
    camera = CameraModel(4, 3, np.eye(3))
    frame = np.arange(12, dtype=np.uint8).reshape(3, 4) * 5
    sample = _sample(frame, EVENTS)
    assert OriginalFrontend(None, camera)(sample) is frame
    np.testing.assert_array_equal(SliceFrontend(None, camera)(sample), event_slice(EVENTS, 4000, 4, 3) * 255)
    eq = HistEqFrontend(None, camera)(sample)
    assert eq.dtype == np.uint8 and eq.max() == 255  # stretched to the full range
    fused = EasFrontend(EasConfig(n=2, sigma_px=0.05, beta=256, gamma=0), camera)(sample)
    assert fused[0, 1] == min(255, frame[0, 1] + frame.max()) and fused[2, 0] == frame[2, 0]


def test_slice_starts_at_the_sample_time():
    camera = CameraModel(4, 3, np.eye(3))
    sample = Sample(index=0, t=0.25, frame=None, events=EVENTS, event_index=3, prev_event_index=0)
    img = SliceFrontend(SliceFrontend.Config(n=1), camera)(sample)
    assert img[1, 3] == 255 and img.sum() == 255  # only the event at t=0.3


@pytest.mark.parametrize("key,value", [("n", 0), ("sigma_px", 0.0), ("beta", 300.0), ("gamma", -1.0)])
def test_eas_config_rejects_out_of_range(key, value):
    from eas_vo.config import build
    from eas_vo.errors import ConfigError

    with pytest.raises(ConfigError, match=key):
        build(EasConfig, {key: value}, "frontend")
