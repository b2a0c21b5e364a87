"""Core types: window lookups in an event stream, the gyro's rates between two times."""

import numpy as np
import pytest

from helpers import random_events


def test_search_times_equals_searchsorted_without_copying(tmp_path):
    from eas_vo.types import search_times

    ev = random_events(100_000, seed=9)
    ev["t"][1000:1010] = ev["t"][1000]  # ties
    queries = np.concatenate([[-1.0, ev["t"][1000], 1e9], np.random.default_rng(0).uniform(0, 1300, 500)])
    np.testing.assert_array_equal(search_times(ev, queries), np.searchsorted(ev["t"], queries, side="left"))
    assert len(search_times(ev[:0], [1.0])) == 1 and search_times(ev[:0], [1.0])[0] == 0



def test_gyro_rates_between_cut_at_readings_and_are_held_outside():
    """Readings every 5 ms of a rate growing 10 rad/s per s: pieces end on readings (none of
    zero length), each piece's rate is its mean, and before or after the readings they are held."""
    from eas_vo.types import ImuSeries

    t = np.arange(0.0, 0.1, 0.005)
    imu = ImuSeries(t, np.zeros((len(t), 3)), np.column_stack([10.0 * t, np.zeros(len(t)), -t]))
    rates, dt = imu.rates_between(0.02, 0.035)
    np.testing.assert_allclose(dt, [0.005, 0.005, 0.005])
    np.testing.assert_allclose(rates[:, 0], [0.225, 0.275, 0.325])
    rates, dt = imu.rates_between(0.0212, 0.0212)
    assert dt.tolist() == [0.0] and rates[0, 0] == pytest.approx(0.212)
    rates, dt = imu.rates_between(0.09, 0.2)  # the last reading is at 0.095 s
    np.testing.assert_allclose(dt, [0.005, 0.105])
    np.testing.assert_allclose(rates[:, 0], [0.925, 0.95])


def test_the_integral_since_start_agrees_with_rates_between():
    """The vectorised integral (the IMU check's) between any two times equals the sum over
    ImuSeries.rates_between (rates linear between readings, held outside them)."""
    from eas_vo.types import ImuSeries

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.003, 0.007, 200))
    imu = ImuSeries(t, np.zeros((len(t), 3)), rng.normal(0, 2.0, (len(t), 3)))
    turned = imu.turned_since_start()
    for t0, t1 in [(t[10], t[20]), (t[10] + 0.001, t[20] - 0.002), (t[0] - 0.02, t[3] + 0.001), (t[-3] - 0.001, t[-1] + 0.03)]:
        rates, dt = imu.rates_between(t0, t1)
        np.testing.assert_allclose(turned(t1) - turned(t0), (rates * dt[:, None]).sum(axis=0), atol=1e-12)
