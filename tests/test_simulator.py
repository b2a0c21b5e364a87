"""The synthetic DAVIS simulator: determinism, HDR scene, sensor models, ground truth and IMU."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.simulator import SimConfig, simulate
from eas_vo.datasets.simulator.generate import DAVIS240_CAMERA, camera_rays
from eas_vo.datasets.simulator.motion import HandHeldMotion
from eas_vo.datasets.simulator.scene import Scene
from eas_vo.datasets.simulator.sensor import ApsModel, DvsModel, EventSimulator


def test_same_seed_same_sequence_other_seed_differs(tmp_path):
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        simulate(SimConfig(duration_s=0.3, seed=seed), tmp_path / name)
    for f in ("events.txt", "groundtruth.txt", "imu.txt", "images/frame_00000001.png"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a" / "events.txt").read_bytes() != (tmp_path / "c" / "events.txt").read_bytes()


def test_scene_radiance_spans_four_decades_and_the_view_is_mostly_dim():
    scene = Scene(np.random.default_rng(0))
    lit = scene.atlas[scene.atlas > 0]
    assert np.log10(np.percentile(lit, 99.99) / np.percentile(lit, 0.1)) >= 4
    motion = HandHeldMotion(np.random.default_rng(1), 10.0)
    rays = camera_rays(DAVIS240_CAMERA)
    dim_fraction = []
    for t in np.linspace(0, 10, 21):
        R, p = motion.pose(t)
        radiance = scene.render(R[0], p[0], rays, (180, 240))
        dim_fraction.append(np.mean(radiance < 0.03))  # < 0.03 exposes to under ~2.4 grey levels
    assert np.mean(dim_fraction) > 0.6


def test_render_sees_parallax_from_translation():
    scene = Scene(np.random.default_rng(0))
    rays = camera_rays(DAVIS240_CAMERA)
    a = scene.render(np.eye(3), np.zeros(3), rays, (180, 240))
    b = scene.render(np.eye(3), np.array([0.05, 0, 0]), rays, (180, 240))
    assert np.abs(np.log(a + 1e-3) - np.log(b + 1e-3)).mean() > 0.05


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


def test_event_times_are_float64_and_sorted_late_in_a_long_sequence():
    model = DvsModel(threshold_sigma=0.0, noise_rate_hz=0.0, dark_noise_rate_hz=0.0, hot_pixel_fraction=0.0, refractory_s=0.0)
    sim = EventSimulator(model, (1, 1), np.random.default_rng(0))
    sim.start(np.array([[1.0]]) - model.log_eps)
    t0 = 1000.0  # where float32 resolution would be 61 us
    ev = sim.step(t0, t0 + 1e-4, np.array([[np.e]]) - model.log_eps)
    np.testing.assert_allclose(ev["t"] - t0, [0.3e-4, 0.6e-4, 0.9e-4], atol=1e-9)


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


def test_motion_speed_grows_and_is_mostly_rotation():
    motion = HandHeldMotion(np.random.default_rng(0), 10.0)
    t = np.linspace(0, 10, 2001)
    speed = np.linalg.norm(motion.angular_velocity(t), axis=1)
    assert speed[t > 7].mean() > 1.5 * speed[t < 3].mean()
    _, p = motion.pose(t)
    assert np.ptp(p, axis=0).max() < 0.2  # centimetres, not metres


def test_ground_truth_and_imu_agree(short_sequence):
    ds = EcdFolderDataset(short_sequence)
    gt, imu = ds.ground_truth, ds.imu
    assert np.median(np.diff(gt.t)) == pytest.approx(0.005) and np.median(np.diff(imu.t)) == pytest.approx(0.005)
    R = Rotation.from_quat(gt.q_w_c)
    omega = (R[:-1].inv() * R[1:]).as_rotvec() / np.diff(gt.t)[:, None]  # body rate between samples
    gyro_mid = 0.5 * (imu.gyro[:-1] + imu.gyro[1:])
    error = gyro_mid - omega
    assert np.linalg.norm(error.mean(0)) < 0.05  # the bias (0.01 rad/s std per axis)
    assert error.std(0).max() < 0.1  # the white noise (0.003 rad/s/sqrt(Hz) at 200 Hz: 0.04)
    assert np.linalg.norm(imu.acc, axis=1).mean() == pytest.approx(9.81, abs=0.3)
