"""The DAVIS sensor models: events (crossings, refractory period, noise) and APS frames."""

import numpy as np
from eas_vo.datasets.simulator.sensor import ApsModel, DvsModel, EventSimulator


def test_events_count_threshold_crossings_with_interpolated_times():
    model = DvsModel(threshold_sigma=0.0, noise_rate_hz=0.0, dark_noise_rate_hz=0.0, hot_pixel_fraction=0.0, refractory_s=0.0)
    sim = EventSimulator(model, (1, 2), np.random.default_rng(0))
    sim.start(np.array([[1.0, 1.0]]) - model.log_eps)
    # Pixel 0: log intensity rises by 1.0 -> floor(1.0 / 0.3) = 3 ON events at 0.3, 0.6, 0.9 of the step.
    # Pixel 1: falls by 0.5 -> 1 OFF event at 0.6 of the step.
    radiance = np.array([[np.e, np.exp(-0.5)]]) - model.log_eps
    ev = sim.step(0.0, 1.0, radiance)
    on, off = ev[ev["x"] == 0], ev[ev["x"] == 1]
    np.testing.assert_allclose(on["t"], [0.3, 0.6, 0.9], atol=1e-5)
    assert (on["p"] == 1).all() and len(off) == 1 and off["p"][0] == 0
    np.testing.assert_allclose(off["t"], [0.6], atol=1e-5)
    assert (np.diff(ev["t"]) >= 0).all()


def test_refractory_period_drops_events():
    model = DvsModel(threshold_sigma=0.0, noise_rate_hz=0.0, dark_noise_rate_hz=0.0, hot_pixel_fraction=0.0, refractory_s=0.5)
    sim = EventSimulator(model, (1, 1), np.random.default_rng(0))
    sim.start(np.array([[1.0]]) - model.log_eps)
    ev = sim.step(0.0, 1.0, np.array([[np.e]]) - model.log_eps)
    np.testing.assert_allclose(ev["t"], [0.3, 0.9], atol=1e-5)  # 0.6 falls within 0.5 s of 0.3


def test_background_noise_grows_in_the_dark():
    model = DvsModel(hot_pixel_fraction=0.0)
    shape = (100, 100)
    counts = {}
    for name, level in (("dark", 0.001), ("bright", 1.0)):
        sim = EventSimulator(model, shape, np.random.default_rng(0))
        img = np.full(shape, level)
        sim.start(img)
        counts[name] = len(sim.step(0.0, 1.0, img))  # static scene: only noise
    assert counts["dark"] > 5 * counts["bright"] > 0


def test_frames_are_noisy_quantised_and_saturate():
    aps = ApsModel()
    rng = np.random.default_rng(0)
    fpn = aps.fixed_pattern((50, 50), rng)
    dark = aps.expose(np.full((50, 50), 0.005), fpn, rng)
    bright = aps.expose(np.full((50, 50), 100.0), fpn, rng)
    assert dark.dtype == np.uint8 and dark.mean() < 2 and dark.std() > 0
    assert (bright == 255).all()

