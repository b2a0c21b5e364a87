"""What the recording readers share: sampling event-only streams."""

import numpy as np

from eas_vo.datasets.recording import event_sample_times


def test_event_sample_times_by_rate_and_by_count():
    t = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(event_sample_times(t, 10.0, 0), np.arange(0, 1.0, 0.1))
    np.testing.assert_array_equal(event_sample_times(t, 10.0, 250), t[::250])
    assert len(event_sample_times(t[:0], 10.0, 0)) == 0


def test_calibration_problems_follow_the_lens_model():
    from eas_vo.datasets.recording import calibration_problem

    assert calibration_problem([226.4, 226.2, 173.6, 133.7, -0.048, 0.0113, -0.0554, 0.0215], 346, 260, "equidistant") is None
    # the 4th coefficient, 5: a fine equidistant k4, no radial-tangential p2 (|p| <= 1)
    assert calibration_problem([226.4, 226.2, 173.6, 133.7, 0.1, 0.1, 0.0, 5.0], 346, 260, "equidistant") is None
    assert "radtan distortion k1 k2 p1 p2 k3 = 0.1 0.1 0 5 0 out of range" in calibration_problem([226.4, 226.2, 173.6, 133.7, 0.1, 0.1, 0.0, 5.0], 346, 260)
    assert "equidistant distortion k1 k2 k3 k4 = 0.1 0.1 0 50 out of range" in calibration_problem(
        [226.4, 226.2, 173.6, 133.7, 0.1, 0.1, 0.0, 50.0], 346, 260, "equidistant")
