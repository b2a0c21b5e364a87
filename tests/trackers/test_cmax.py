"""`cmax` on events the project's simulator makes under a known constant motion: the angular
velocity it recovers, and what it says of noise alone and of translation.

The bound: the contrast peak is found to a fraction of a pixel (the solver stops within ~0.005
px, the bilinear votes and the texture leave ~0.1 px), so over a window in which the motion
displaces the image centre by D px, |omega| is off by at most ~0.1 / D relative. The windows
below displace it by 2 * HALF_DISPLACEMENT_PX = 24 px: 2 % is 0.5 px, a bound with room for the
noise events (the simulator's shot noise and hot pixels stay on). The sensor's photoreceptor
low-pass is off here (an ideal pixel): with it, dim pixels lag bright ones by several ms, which
biases the optimum (docs/cmax.md measures how much); this test checks the estimator.
"""

import functools
import itertools

import numpy as np
import pytest

from eas_vo import config as config_module
from eas_vo.datasets.simulator.generate import SENSORS, SimConfig, simulate_events
from eas_vo.datasets.simulator.motion import ConstantMotion
from eas_vo.datasets.simulator.sensor import DvsModel
from eas_vo.errors import ConfigError
from eas_vo.geometry.rotations import geodesic_angle, matrix_to_rotvec, rotvec_to_matrix
from eas_vo.trackers.cmax import REFERENCE_PIXELS, CmaxConfig, CmaxTracker, Window, _bounded, _integrated, _newton
from eas_vo.types import Sample

HALF_DISPLACEMENT_PX = 12.0
R_W_C0 = rotvec_to_matrix(np.array([0.05, 0.15, -0.03]))  # the hand-held start: the room's textured boxes ahead
WARM_UP_S = 0.01


@functools.lru_cache(maxsize=None)
def events_of(
    omega_deg: tuple, sensor: str, duration_s: float, velocity=(0.0, 0.0, 0.0), p0=(0.0, 0.0, 0.0), ideal: bool = True
) -> np.ndarray:
    dvs = DvsModel(cutoff_hz=0.0) if ideal else DvsModel()
    motion = ConstantMotion(np.radians(omega_deg), velocity, R_W_C0 if not any(velocity) else np.eye(3), p0)
    events, _ = simulate_events(SimConfig(duration_s=duration_s, seed=5, dvs=dvs, camera=SENSORS[sensor]), motion)
    return events


@pytest.mark.parametrize(
    "sensor,omega_deg",
    [
        ("davis240", (200.0, 0.0, 0.0)),
        ("davis240", (0.0, 0.0, 300.0)),  # roll: the image centre does not move, its rim does
        ("davis240", (346.4, 346.4, 346.4)),  # 600 deg/s about the diagonal
        ("davis240", (0.0, -1000.0, 0.0)),
        ("davis346", (150.0, -480.0, 90.0)),  # 510 deg/s, the equidistant lens
    ],
)
def test_cmax_recovers_a_constant_angular_velocity_within_2_percent(sensor, omega_deg):
    camera = SENSORS[sensor].model()
    omega = np.radians(omega_deg)
    span_s = 2 * HALF_DISPLACEMENT_PX / (np.linalg.norm(omega) * camera.focal_px)
    events = events_of(omega_deg, sensor, WARM_UP_S + span_s + 0.002)
    window = events[(events["t"] >= WARM_UP_S) & (events["t"] < WARM_UP_S + span_s)]
    tracker = CmaxTracker(CmaxConfig(init="search"), camera)  # no start given: the coarse search finds it
    found = tracker.measure(window, 0.0, span_s)
    error = np.linalg.norm(found.omega - omega) / np.linalg.norm(omega)
    assert error < 0.02, f"omega {np.degrees(found.omega).round(1)} deg/s for {omega_deg}: {100 * error:.2f} % off"
    assert found.gain > 1.2 and found.focus > CmaxConfig().weak_focus
    assert 0 < found.sigma_rad_s < np.linalg.norm(omega)


def samples_of(events: np.ndarray, times: np.ndarray):
    starts = np.searchsorted(events["t"], times)
    return [
        Sample(n, float(t), None, events, int(first), int(starts[n - 1]) if n else 0)
        for n, (t, first) in enumerate(zip(times, starts))
    ]


def statuses(tracker: CmaxTracker, events: np.ndarray, times: np.ndarray):
    return [tracker.process(None, s.t, sample=s) for s in samples_of(events, times)]


def test_a_still_camera_seeing_only_noise_measures_nothing():
    events = events_of((0.0, 0.0, 0.0), "davis240", 0.3, ideal=False)  # shot noise, leaks, 500 Hz hot pixels
    results = statuses(
        CmaxTracker(CmaxConfig(window_events=15000), SENSORS["davis240"].model()), events, np.arange(0.05, 0.3, 0.05)
    )
    assert results[0][0].status == "first"
    assert all(r.status in ("weak", "lost") and "in focus" in r.reason for r, _ in results[1:]), [
        (r.status, r.reason) for r, _ in results
    ]


def test_a_camera_moving_forward_before_a_near_box_is_not_reported_ok():
    # 2 m/s along the optical axis, 1 m from the box ahead: the image expands, no rotation explains it
    events = events_of((0.0, 0.0, 0.0), "davis240", 0.1, velocity=(0.0, 0.0, 2.0), p0=(0.0, 0.0, 1.0), ideal=False)
    results = statuses(
        CmaxTracker(CmaxConfig(window_events=15000), SENSORS["davis240"].model()), events, np.arange(0.02, 0.1, 0.02)
    )
    assert all(r.status in ("weak", "lost") for r, _ in results[1:]), [(r.status, r.reason) for r, _ in results]


def test_intervals_are_cut_into_windows_by_count_or_time_and_integrated():
    omega_deg = (0.0, -1000.0, 0.0)
    events = events_of(omega_deg, "davis240", 0.04)
    camera = SENSORS["davis240"].model()
    times = np.array([0.015, 0.035])
    between = int(np.sum((events["t"] >= times[0]) & (events["t"] < times[1])))
    for cfg, n_windows in ((CmaxConfig(window_events=between // 3), 3), (CmaxConfig(window_s=0.005), 4)):
        tracker = CmaxTracker(cfg, camera)
        (_, _), (record, (edge,)) = statuses(tracker, events, times)
        assert len(tracker.windows) == n_windows
        assert record.status == "ok" and record.events == between
        truth = rotvec_to_matrix(np.radians(omega_deg) * 0.02)

        assert geodesic_angle(edge.R_i_j, truth) < 0.02 * np.radians(1000.0) * 0.02
        assert 0 < edge.sigma_rad < 0.35  # the rotation itself; SIGMA_SCALE says how it is scaled


def test_bad_settings_are_one_line_errors():
    with pytest.raises(ConfigError, match="weak_focus"):
        config_module.resolve(None, {"tracker": "cmax"}, ["tracker.lost_focus=1.2", "tracker.weak_focus=1.1"])
    with pytest.raises(ConfigError, match="init"):
        config_module.resolve(None, {"tracker": "cmax"}, ["tracker.init=gyro"])


@pytest.mark.parametrize("metric_scale", [(1.0, 1.0, 1.0), (0.6, 1.5, 1.0), (1.5, 0.6, 1.4)])
def test_newton_finds_the_peak_in_a_metric_half_wrong_in_a_few_evaluations(metric_scale):
    """The metric is the previous window's curvature: on synthetic:default it differs from the
    window's own by 3-48 %."""
    rng = np.random.default_rng(3)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    H = (Q * np.array([0.005, 0.03, 0.1])) @ Q.T  # synthetic:default's range of curvatures [per px^2]
    top = np.array([1.2, -0.8, 0.5])  # px from the start: the gyro's start is 0.1-1.8 px off there
    costs = []

    def cost(p):
        d = p - top
        costs.append(0.5 * d @ H @ d + 0.001 * np.sum(d**4))
        return costs[-1], H @ d + 0.004 * d**3

    metric = (Q * (np.array([0.005, 0.03, 0.1]) * metric_scale)) @ Q.T
    p, f = _newton(cost, np.zeros(3), metric)
    assert np.linalg.norm(p - top) < 0.05
    assert f == min(costs) and len(costs) <= 12  # the lowest point it evaluated
    p, f = _newton(cost, np.zeros(3), None)  # the curvature measured at the start
    assert np.linalg.norm(p - top) < 0.05


def test_an_interval_is_measured_only_from_its_own_events():
    """Events missing over 0.06-0.14 s (a dropped transfer) of a camera panning at 60 deg/s: the
    intervals inside the gap hold no event and are lost (not measured from the events before
    it), those the gap cuts into are weak (the rate extrapolated over most of them)."""
    events = events_of((0.0, 60.0, 0.0), "davis240", 0.2, ideal=False)
    events = events[(events["t"] < 0.06) | (events["t"] >= 0.14)]
    times = np.array([0.02, 0.05, 0.08, 0.11, 0.15, 0.18])
    results = statuses(CmaxTracker(CmaxConfig(), SENSORS["davis240"].model()), events, times)
    records = [r for r, _ in results]
    assert records[3].status == "lost" and records[3].events == 0 and not results[3][1], records[3]
    for k in (2, 4):
        assert records[k].status == "weak" and "miss part of the interval" in records[k].reason, records[k]
        assert results[k][1][0].inliers == 0  # a weak window is no confident pair for the gyro's check
    inside = [(events["t"] >= a) & (events["t"] < b) for a, b in itertools.pairwise(times)]
    assert all(
        0 < r.events <= m.sum() for m, r in zip(inside, records[1:]) if r.status != "lost"
    )  # hot pixels left out


def test_a_window_of_any_length_holds_a_bounded_number_of_windows():
    """window_s = 1 ms over an interval of 1000 s (times in the wrong unit) is not cut into a
    million windows: a window under min_events makes the frame lost before any is made; a
    window of time holds at most 2 * window_events events (the memory one takes)."""
    events = events_of((0.0, 60.0, 0.0), "davis240", 0.05)
    tracker = CmaxTracker(CmaxConfig(window_s=0.001), SENSORS["davis240"].model())
    assert tracker._windows(events, 0.0, 1000.0) is None
    assert len(tracker._windows(events, 0.0, 0.05)) == 50
    dense = CmaxTracker(CmaxConfig(window_s=0.05, window_events=1000), SENSORS["davis240"].model())
    windows = dense._windows(events, 0.0, 0.05)  # one window of time holding many times window_events
    assert max(len(w) for w, *_ in windows) <= 2 * 1000 and sum(len(w) for w, *_ in windows) == len(events)


def window(rotvec_deg, covariance_rad2, t0, t1):
    """A Window turning by rotvec_deg over [t0, t1] [s] whose rotation over it has covariance_rad2."""
    dt = t1 - t0
    return Window(
        np.radians(rotvec_deg) / dt, 0.0, 1.1, 1.02, 5000, t0, t1, 10, 0.1, covariance=covariance_rad2 / dt**2
    )


def test_an_intervals_covariance_is_its_windows_carried_to_its_end():
    """Each window's omega error turns its factor, and the windows after it carry that turn into
    the frame the interval ends in (RelativeRotation's convention): sampled omega errors give
    errors whose NEES against _integrated's covariance has mean 3; adding the windows'
    covariances without carrying them does not, once a later window turns by 30 degrees."""
    windows = [
        window([0.0, 2.0, 0.0], np.diag([1e-4, 1e-6, 1e-6]), 0.0, 0.01),
        window([0.0, 0.0, 30.0], 1e-8 * np.eye(3), 0.01, 0.02),
    ]
    R, covariance = _integrated(windows)
    rng = np.random.default_rng(0)
    nees, naive = [], []
    summed = sum((w.t1 - w.t0) ** 2 * w.covariance for w in windows)
    for _ in range(4000):
        R_drawn = np.eye(3)
        for w in windows:
            dt = w.t1 - w.t0
            R_drawn = R_drawn @ rotvec_to_matrix((w.omega + rng.multivariate_normal(np.zeros(3), w.covariance)) * dt)
        delta = matrix_to_rotvec(R.T @ R_drawn)  # R_drawn = R Exp(delta)
        nees.append(delta @ np.linalg.solve(covariance, delta))
        naive.append(delta @ np.linalg.solve(summed, delta))
    assert abs(np.mean(nees) - 3.0) < 0.15, np.mean(nees)
    assert np.mean(naive) > 10.0, np.mean(naive)


def test_a_weak_interval_states_at_least_its_sigma_on_every_axis():
    covariance = np.diag([1e-6, 4e-6, 1e-2])
    floored = _bounded(covariance, 0.01)
    np.testing.assert_allclose(np.linalg.eigvalsh(floored), [1e-4, 1e-4, 1e-2])
    assert np.allclose(_bounded(None, 0.0), np.eye(3)) and np.allclose(_bounded(100 * np.eye(3), 0.0), np.eye(3))


def test_the_focus_thresholds_stand_as_far_above_the_noise_on_every_sensor():
    """Stated for the DAVIS240's pixels; a quarter of them (twice the noise of the focus) doubles
    their excess over 1."""
    config = CmaxConfig()
    assert CmaxTracker(config, SENSORS["davis240"].model()).thresholds == (
        config.lost_focus,
        config.lost_gain,
        config.weak_focus,
    )
    small = SENSORS["davis240"].resized(120, 90)
    assert small.width * small.height * 4 == REFERENCE_PIXELS
    np.testing.assert_allclose(
        CmaxTracker(config, small.model()).thresholds,
        [1 + 2 * (config.lost_focus - 1), 1 + 2 * (config.lost_gain - 1), 1 + 2 * (config.weak_focus - 1)],
    )
