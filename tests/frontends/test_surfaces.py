"""TS and SITS: known answers, and cross-checks against tonic and dv-processing."""

import numpy as np
import pytest

from eas_vo.camera import CameraModel
from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.frontends.surfaces import SitsConfig, SitsFrontend, TsConfig, TsFrontend
from eas_vo.types import EVENT_DTYPE, Sample
from helpers import EVENT_WINDOWS, require


def random_events(n, width, height, seed=0, t_scale=1.0):
    rng = np.random.default_rng(seed)
    ev = np.empty(n, EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, int(1e6 * t_scale), n)).astype(float) / 1e6
    ev["x"], ev["y"] = rng.integers(0, width, n), rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    return ev


def camera(width, height):
    return CameraModel(width, height, np.eye(3))


def sits_reference(events, width, height, r):
    """The paper's definition, written plainly."""
    S = np.zeros((height, width), int)
    for x, y in zip(events["x"].astype(int), events["y"].astype(int)):
        centre = S[y, x]
        window = S[max(0, y - r) : y + r + 1, max(0, x - r) : x + r + 1]
        window[window > centre] -= 1
        S[y, x] = (2 * r + 1) ** 2
    return S


def run_sits(events, width, height, config):
    frontend = SitsFrontend(config, camera(width, height))
    frontend.consume(events)
    return frontend


def test_sits_by_hand():
    # r = 1 on a 4x3 sensor: events at (1,1), (2,1), (1,1).
    ev = np.zeros(3, EVENT_DTYPE)
    ev["x"], ev["y"] = [1, 2, 1], [1, 1, 1]
    S = run_sits(ev, 4, 3, SitsConfig(r=1)).surface[0]
    # after (1,1): 9 at (1,1). After (2,1): (1,1) 9 > 0 -> 8, (2,1) = 9.
    # After (1,1) again: centre 8, neighbour (2,1) = 9 > 8 -> 8, centre = 9.
    expected = np.zeros((3, 4), int)
    expected[1, 1], expected[1, 2] = 9, 8
    np.testing.assert_array_equal(S, expected)


def test_sits_symmetric_default_matches_the_definition():
    ev = random_events(5000, 40, 30, seed=1)
    np.testing.assert_array_equal(run_sits(ev, 40, 30, SitsConfig(r=3)).surface[0], sits_reference(ev, 40, 30, 3))


def test_sits_split_polarity_keeps_two_surfaces():
    ev = random_events(3000, 30, 20, seed=2)
    split = run_sits(ev, 30, 20, SitsConfig(r=2, polarity="split")).surface
    for p in (0, 1):
        np.testing.assert_array_equal(split[p], sits_reference(ev[ev["p"] == p], 30, 20, 2))


def test_incremental_consumption_equals_one_batch_and_reset_clears():
    ev = random_events(4000, 30, 20, seed=3)
    whole = run_sits(ev, 30, 20, SitsConfig()).surface
    frontend = SitsFrontend(SitsConfig(), camera(30, 20))
    bounds = [0, 1000, 1001, 2500, 4000]
    for k, (a, b) in enumerate(zip(bounds, bounds[1:])):
        image = frontend(Sample(k, float(ev["t"][b - 1]), None, ev, b, a))
    np.testing.assert_array_equal(frontend.surface, whole)
    assert image.dtype == np.uint8 and image.shape == (20, 30)
    frontend.reset()
    assert not frontend.surface.any()


def dv_sits(events, width, height):
    dv = pytest.importorskip("dv_processing", reason="dv-processing (the test extra's peer) is not installed")
    store = dv.EventStore()
    for t, x, y, p in zip((events["t"] * 1e6).astype(np.int64), events["x"], events["y"], events["p"]):
        store.push_back(int(t), int(x), int(y), bool(p))
    surface = dv.SpeedInvariantTimeSurface((width, height))
    surface.accept(store)
    return surface


def dv_values(surface, width, height):
    return np.array([[surface.at(y, x) for x in range(width)] for y in range(height)])


@pytest.mark.parametrize("width,height,n,seed", [(30, 20, 3000, 0), (240, 180, 20000, 1), (9, 9, 400, 2)])
def test_sits_dv_compatible_equals_dv_processing_on_random_events(width, height, n, seed):
    ev = random_events(n, width, height, seed=seed)
    ours = run_sits(ev, width, height, SitsConfig(r=4, dv_compatible=True))
    peer = dv_sits(ev, width, height)
    np.testing.assert_array_equal(ours.surface[0], dv_values(peer, width, height))
    np.testing.assert_array_equal(ours.render(), peer.generateFrame().image.reshape(height, width))
    # the paper's symmetric window differs wherever dv-processing's interior window applies
    symmetric = run_sits(ev, width, height, SitsConfig(r=4)).surface[0]
    assert np.array_equal(symmetric, ours.surface[0]) == (min(width, height) <= 9)


@pytest.mark.parametrize("name", ["boxes_rotation", "poster_rotation", "dynamic_rotation"])
def test_sits_dv_compatible_equals_dv_processing_on_real_events(name):
    ds = EcdFolderDataset(require(EVENT_WINDOWS / name))
    ev = np.asarray(ds.events())
    ours = run_sits(ev, 240, 180, SitsConfig(r=4, dv_compatible=True))
    np.testing.assert_array_equal(ours.surface[0], dv_values(dv_sits(ev, 240, 180), 240, 180))


def test_ts_equals_tonic_time_surfaces():
    F = pytest.importorskip("tonic.functional", reason="tonic (the test extra's peer) is not installed")

    width, height, tau_us, dt_us = 30, 20, 20_000.0, 50_000.0
    ev = random_events(3000, width, height, seed=4, t_scale=1.0)
    tonic_events = np.zeros(len(ev), dtype=[("x", int), ("y", int), ("t", int), ("p", int)])
    tonic_events["x"], tonic_events["y"], tonic_events["p"] = ev["x"], ev["y"], ev["p"]
    tonic_events["t"] = np.round(ev["t"] * 1e6).astype(int)
    surfaces = F.to_timesurface_numpy(tonic_events, (width, height, 2), dt=dt_us, tau=tau_us)
    frontend = TsFrontend(TsConfig(tau_s=tau_us * 1e-6, polarity="split"), camera(width, height))
    start_us = tonic_events["t"][0]
    from eas_vo.frontends.surfaces import time_surface
    from eas_vo.types import search_times

    # tonic's slice i holds events in [start + i dt, start + (i+1) dt) and renders at start + (i+1) dt
    consumed = 0
    for i, expected in enumerate(surfaces):
        t_us = start_us + (i + 1) * dt_us
        upto = int(search_times(ev, [t_us * 1e-6])[0])  # the events before the render time
        frontend.consume(ev[consumed:upto])
        consumed = upto
        np.testing.assert_allclose(
            time_surface(frontend.latest, t_us * 1e-6, tau_us * 1e-6), expected, rtol=1e-9, atol=1e-12
        )


def test_ts_render_merged_and_split():
    ev = np.zeros(2, EVENT_DTYPE)
    ev[0] = (0.0, 1, 1, 1)
    ev[1] = (0.01, 2, 1, 0)
    merged = TsFrontend(TsConfig(tau_s=0.01), camera(4, 3))
    merged.consume(ev)
    image = merged.render(0.01)
    assert image[1, 2] == 255 and image[1, 1] == round(255 * np.exp(-1)) and image[0, 0] == 0
    split = TsFrontend(TsConfig(tau_s=0.01, polarity="split"), camera(4, 3))
    split.consume(ev)
    image = split.render(0.01)
    assert image[1, 2] == 0 and image[1, 1] == round(127.5 + 127.5 * np.exp(-1)) and image[0, 0] == 128
