"""What the recording readers share: sampling event-only streams."""

import numpy as np

from eas_vo.datasets.recording import event_sample_times


def test_event_sample_times_by_rate_and_by_count():
    t = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(event_sample_times(t, 10.0, 0), np.arange(0, 1.0, 0.1))
    np.testing.assert_array_equal(event_sample_times(t, 10.0, 250), t[::250])
    assert len(event_sample_times(t[:0], 10.0, 0)) == 0
