"""What the recording readers share: sampling event-only streams, reading poses."""

import numpy as np

from eas_vo.datasets.recording import event_sample_times, pose_series


def test_event_sample_times_by_rate_and_by_count():
    t = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(event_sample_times(t, 10.0, 0), np.arange(0, 1.0, 0.1))
    np.testing.assert_array_equal(event_sample_times(t, 10.0, 250), t[::250])
    assert len(event_sample_times(t[:0], 10.0, 0)) == 0


def test_poses_written_with_nine_decimals_read_back_as_written_and_others_are_normalised():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    text = "".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in np.column_stack([np.arange(500.0), np.zeros((500, 3)), q]))
    table = np.loadtxt(text.splitlines())
    assert np.abs(np.linalg.norm(table[:, 4:], axis=1) - 1).max() > 1e-12  # the text is not unit to the last bit
    np.testing.assert_array_equal(pose_series("gt", table).q_w_c, table[:, 4:])
    table[:, 4:] *= 1.001
    np.testing.assert_allclose(np.linalg.norm(pose_series("gt", table).q_w_c, axis=1), 1.0, rtol=0, atol=1e-15)
