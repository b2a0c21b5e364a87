"""The DAVIS sensor models on tiny scenes with known answers: threshold crossings, the
refractory period, the photoreceptor's intensity-dependent delay, noise rates, threshold
mismatch, and APS frames."""

import numpy as np
import pytest

from eas_vo.datasets.simulator.sensor import ApsModel, DvsModel, EventSimulator

#: An ideal pixel: no filter, no noise, exact thresholds of 0.3.
IDEAL = DvsModel(
    contrast_threshold=0.3,
    threshold_sigma=0.0,
    cutoff_hz=0.0,
    shot_noise_rate_hz=0.0,
    leak_rate_hz=0.0,
    hot_pixel_fraction=0.0,
    refractory_s=0.0,
)


def test_events_count_threshold_crossings_with_interpolated_times():
    sim = EventSimulator(IDEAL, (1, 2), np.random.default_rng(0))
    sim.start(np.array([[1.0, 1.0]]) - IDEAL.log_eps)
    # Pixel 0: log intensity rises by 1.0 -> floor(1.0 / 0.3) = 3 ON events at 0.3, 0.6, 0.9 of the step.
    # Pixel 1: falls by 0.5 -> 1 OFF event at 0.6 of the step.
    radiance = np.array([[np.e, np.exp(-0.5)]]) - IDEAL.log_eps
    ev, truth = sim.step(0.0, 1.0, radiance)
    on, off = ev[ev["x"] == 0], ev[ev["x"] == 1]
    np.testing.assert_allclose(on["t"], [0.3, 0.6, 0.9], atol=1e-5)
    assert (on["p"] == 1).all() and len(off) == 1 and off["p"][0] == 0
    np.testing.assert_allclose(off["t"], [0.6], atol=1e-5)
    assert (np.diff(ev["t"]) >= 0).all()
    assert not truth.noise.any()
    np.testing.assert_allclose(truth.latency_s, 0.0, atol=1e-9)  # unfiltered: no delay


def test_refractory_period_drops_events():
    model = DvsModel(**{**IDEAL.__dict__, "refractory_s": 0.5})
    sim = EventSimulator(model, (1, 1), np.random.default_rng(0))
    sim.start(np.array([[1.0]]) - model.log_eps)
    ev, _ = sim.step(0.0, 1.0, np.array([[np.e]]) - model.log_eps)
    np.testing.assert_allclose(ev["t"], [0.3, 0.9], atol=1e-5)  # 0.6 falls within 0.5 s of 0.3


def first_event_after_a_step(model, before, after, dt=1e-4, horizon=2.0):
    """Time of the first event of one pixel whose radiance steps from `before` to `after` at 0."""
    sim = EventSimulator(model, (1, 1), np.random.default_rng(0))
    sim.start(np.array([[before]]))
    for k in range(int(horizon / dt)):
        ev, truth = sim.step(k * dt, (k + 1) * dt, np.array([[after]]))
        if len(ev):
            return ev["t"][0], truth.latency_s[0]
    return None, None


@pytest.mark.parametrize("illumination", [1.0, 0.1, 0.01])
def test_a_step_of_light_fires_after_the_first_order_filters_delay(illumination):
    """lp(t) = a + D (1 - exp(-t / tau)) reaches a + c at t = -tau ln(1 - c / D), with
    tau = 1 / (2 pi cutoff inten01(after)): the darker, the later."""
    model = DvsModel(**{**IDEAL.__dict__, "cutoff_hz": 30.0})
    before, after = 0.5 * illumination, 1.5 * illumination  # a 3x step, log D = 1.10
    t_event, latency = first_event_after_a_step(model, before, after)
    D = np.log(after + model.log_eps) - np.log(before + model.log_eps)
    tau = 1.0 / (2 * np.pi * model.cutoff_hz * model.inten01(np.array(after)))
    expected = -tau * np.log(1.0 - model.contrast_threshold / D)
    assert t_event == pytest.approx(expected, rel=0.2)
    assert latency == pytest.approx(t_event, abs=1e-3)  # the unfiltered signal crossed at once


def test_the_delay_grows_as_light_falls():
    model = DvsModel(**{**IDEAL.__dict__, "cutoff_hz": 30.0})
    delays = [first_event_after_a_step(model, 0.5 * s, 1.5 * s)[0] for s in (1.0, 0.1, 0.01)]
    assert delays[0] < delays[1] < delays[2]


@pytest.mark.parametrize("level", [0.0, 1.0])
def test_a_static_scene_fires_noise_at_the_configured_rate(level):
    """Shot noise (5 Hz in the dark, a quarter of that at white) plus leak (0.1 Hz): the count
    on a static 60x60 scene over 4 s within 4 Poisson sigmas (and 10 %) of the expected one."""
    model = DvsModel(hot_pixel_fraction=0.0)
    shape, duration = (60, 60), 4.0
    sim = EventSimulator(model, shape, np.random.default_rng(1))
    image = np.full(shape, level * model.white_radiance)
    sim.start(image)
    events, truth = sim.step(0.0, duration, image)
    expected = (model.noise_rate_hz(image.ravel()) + sim.leak_rate).sum() * duration
    assert truth.noise.all()
    assert abs(len(events) - expected) < min(4 * np.sqrt(expected), 0.1 * expected), (len(events), expected)
    leak_and_half_shot = (sim.leak_rate.sum() + 0.5 * model.noise_rate_hz(image.ravel()).sum()) * duration
    assert abs((events["p"] == 1).sum() - leak_and_half_shot) < 5 * np.sqrt(leak_and_half_shot)


def test_bright_scenes_are_quieter():
    model = DvsModel(hot_pixel_fraction=0.0)
    rates = model.noise_rate_hz(np.array([0.0, 0.01, model.white_radiance]))
    assert rates[0] > rates[1] > rates[2] == pytest.approx(0.25 * model.shot_noise_rate_hz, rel=0.1)


def test_thresholds_spread_as_configured():
    model = DvsModel(contrast_threshold=0.2, threshold_sigma=0.05)
    sim = EventSimulator(model, (200, 200), np.random.default_rng(2))
    for c in (sim.c_pos, sim.c_neg):
        assert c.mean() == pytest.approx(0.2, abs=0.002) and c.std() == pytest.approx(0.05, rel=0.05)


def test_frames_are_noisy_quantised_and_saturate():
    aps = ApsModel()
    rng = np.random.default_rng(0)
    fpn = aps.fixed_pattern((50, 50), rng)
    dark = aps.expose(np.full((50, 50), 0.005), fpn, rng)
    bright = aps.expose(np.full((50, 50), 100.0), fpn, rng)
    assert dark.dtype == np.uint8 and dark.mean() < 2 and dark.std() > 0
    assert (bright == 255).all()


def _numpy_crossings(sim, t0, t1, ref, v0, v1):
    """The k-th crossings of all pixels, k = 1, 2, ..., written with numpy: the reference the
    compiled loops must equal bit for bit (level, time [s], direction, pixel, k)."""
    diff = v1 - ref
    n_pos = np.floor(np.maximum(diff, 0) / sim.c_pos).astype(np.int64)
    n_neg = np.floor(np.maximum(-diff, 0) / sim.c_neg).astype(np.int64)
    for k in range(1, int((n_pos + n_neg).max(initial=0)) + 1):
        pix = np.flatnonzero(n_pos + n_neg >= k)
        positive = n_pos[pix] > 0
        level = ref[pix] + k * np.where(positive, sim.c_pos[pix], -sim.c_neg[pix])
        span = v1[pix] - v0[pix]
        frac = np.clip((level - v0[pix]) / np.where(span == 0, 1e-12, span), 0.0, 1.0)
        yield pix, positive, level, t0 + frac.astype(np.float64) * (t1 - t0), k


def test_the_compiled_crossing_loops_equal_the_numpy_reference():
    """Signal events (with the refractory period) and the ring of unfiltered crossings from the
    compiled per-pixel loops: bit for bit those of the numpy formulation, in its order."""
    shape = (30, 40)
    n = shape[0] * shape[1]
    rng = np.random.default_rng(4)
    sim = EventSimulator(DvsModel(), shape, np.random.default_rng(5))
    ref = rng.normal(0, 1, n).astype(np.float32)
    v0 = (ref + rng.normal(0, 0.1, n)).astype(np.float32)
    v1 = (v0 + rng.normal(0, 0.8, n)).astype(np.float32)
    v1[:50] = v0[:50]  # no change: span 0
    sim.ref, sim.last_t = ref.copy(), rng.uniform(-1e-3, 1e-3, n)
    last_t = sim.last_t.copy()
    events, levels = sim._crossings(0.001, 0.003, v0, v1)

    expected, expected_levels = [], []
    for pix, positive, level, t, _ in _numpy_crossings(sim, 0.001, 0.003, ref, v0, v1):
        keep = t - last_t[pix] >= sim.model.refractory_s
        pix, t, positive, level = pix[keep], t[keep], positive[keep], level[keep]
        last_t[pix] = t
        expected.append(np.rec.fromarrays([t, pix % shape[1], pix // shape[1], positive], dtype=events.dtype))
        expected_levels.append(level)
    assert len(events) > 1000
    assert events.tobytes() == np.concatenate(expected).tobytes()
    assert levels.tobytes() == np.concatenate(expected_levels).astype(np.float32).tobytes()
    assert sim.last_t.tobytes() == last_t.tobytes()

    sim.raw_ref, sim.last_raw = ref.copy(), v0
    ring = [a.copy() for a in (sim.ring_level, sim.ring_t, sim.ring_up, sim.ring_next)]
    sim._record_raw_crossings(0.001, 0.003, v1)
    for pix, positive, level, t, _ in _numpy_crossings(sim, 0.001, 0.003, ref, v0, v1):
        slot = ring[3][pix] % sim.HISTORY
        ring[0][pix, slot], ring[1][pix, slot], ring[2][pix, slot] = level, t, positive
        ring[3][pix] += 1
    for got, want in zip((sim.ring_level, sim.ring_t, sim.ring_up, sim.ring_next), ring):
        assert got.tobytes() == want.tobytes()
