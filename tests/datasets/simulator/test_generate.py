"""The simulated sequence as written: determinism, event times, ground truth and IMU, any
sensor size and lens."""

import dataclasses
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.simulator import SimConfig, simulate
from eas_vo.datasets.simulator.generate import SENSORS, camera_rays
from eas_vo.datasets.simulator.sensor import DvsModel, EventSimulator


def test_same_seed_same_sequence_other_seed_differs(tmp_path):
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        simulate(SimConfig(duration_s=0.3, seed=seed), tmp_path / name)
    for f in ("events.txt", "groundtruth.txt", "imu.txt", "images/frame_00000001.png"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a" / "events.txt").read_bytes() != (tmp_path / "c" / "events.txt").read_bytes()


def test_a_sequence_is_cached_under_its_values_not_their_python_types():
    import dataclasses

    from eas_vo.datasets.simulator.generate import SIMULATOR_VERSION

    assert SimConfig(speed=4).fingerprint() == SimConfig(speed=4.0).fingerprint() != SimConfig(speed=4.5).fingerprint()
    assert SimConfig(seed=3).fingerprint() != SimConfig(seed=4).fingerprint()
    # the default's key is what it was before types were normalised and the camera and the
    # translation scale could change: its cached folder stays valid
    before = {
        key: value
        for key, value in dataclasses.asdict(SimConfig()).items()
        if key not in ("camera", "translation_scale")
    }
    assert SimConfig().fingerprint() == repr((SIMULATOR_VERSION, before))
    assert SimConfig(camera=SENSORS["davis346"]).fingerprint() != SimConfig().fingerprint()


def test_event_times_are_float64_and_sorted_late_in_a_long_sequence():
    model = DvsModel(
        contrast_threshold=0.3,
        threshold_sigma=0.0,
        cutoff_hz=0.0,
        shot_noise_rate_hz=0.0,
        leak_rate_hz=0.0,
        hot_pixel_fraction=0.0,
        refractory_s=0.0,
    )
    sim = EventSimulator(model, (1, 1), np.random.default_rng(0))
    sim.start(np.array([[1.0]]) - model.log_eps)
    t0 = 1000.0  # where float32 resolution would be 61 us
    ev, _ = sim.step(t0, t0 + 1e-4, np.array([[np.e]]) - model.log_eps)
    np.testing.assert_allclose(ev["t"] - t0, [0.3e-4, 0.6e-4, 0.9e-4], atol=1e-9)


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


def test_a_davis346_fisheye_sequence_is_written_at_its_size_with_its_lens(tmp_path):
    camera = SENSORS["davis346"]
    simulate(SimConfig(duration_s=0.3, seed=2, camera=camera), tmp_path / "fisheye")
    dataset = EcdFolderDataset(tmp_path / "fisheye")
    assert (dataset.camera.model, dataset.camera.width, dataset.camera.height) == ("equidistant", 346, 260)
    np.testing.assert_array_equal(dataset.camera.K, camera.model().K)
    np.testing.assert_array_equal(dataset.camera.dist, camera.dist)
    assert dataset.load_frame(0).shape == (260, 346)
    events = dataset.events()
    assert events["x"].max() == 345 and events["y"].max() == 259  # events over the whole sensor


def test_the_rendered_rays_are_those_of_the_lens():
    """Each pixel's ray lands back on it: the scene is seen through the camera's own lens."""
    for name, atol_px in (("davis346", 1e-3), ("davis240", 0.01)):  # radtan: cv2.undistortPoints' 5 steps
        camera = SENSORS[name].model()
        u, v = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
        np.testing.assert_allclose(
            camera.project(camera_rays(camera)), np.stack([u.ravel(), v.ravel()], 1), rtol=0, atol=atol_px
        )


#: What a 0.3 s sequence (seed 3, the default camera) holds, hashed: its events, frames, frame
#: times, IMU and poses, as simulated before the simulator's loops were compiled and its ray
#: cast overlapped with the sensor model. A change of any event (or pixel, or reading) shows
#: here; one meant to change them bumps SIMULATOR_VERSION and this value.
SHORT_SEQUENCE_SHA256 = "bf85b3f89af9d999"


def test_a_short_sequence_is_what_it_always_was(tmp_path):
    import hashlib

    simulate(SimConfig(duration_s=0.3, seed=3), tmp_path / "s")
    ds = EcdFolderDataset(tmp_path / "s")
    digest = hashlib.sha256(np.asarray(ds.events()).tobytes())
    for k in range(len(ds.frame_times())):
        digest.update(ds.load_frame(k).tobytes())
    for values in (
        ds.frame_times(),
        ds.imu.t,
        ds.imu.acc,
        ds.imu.gyro,
        ds.ground_truth.t,
        ds.ground_truth.p_w_c,
        ds.ground_truth.q_w_c,
    ):
        digest.update(np.ascontiguousarray(values).tobytes())
    assert len(ds.events()) == 286_785
    assert digest.hexdigest()[:16] == SHORT_SEQUENCE_SHA256


def test_a_translation_scale_of_one_keeps_every_earlier_sequences_cache_key():
    from eas_vo.datasets.simulator import SimConfig

    assert "translation_scale" not in SimConfig().fingerprint()
    assert SimConfig(translation_scale=1).fingerprint() == SimConfig().fingerprint()
    assert SimConfig(translation_scale=2.0).fingerprint() != SimConfig().fingerprint()


def test_the_progress_bar_counts_simulated_seconds_to_its_end(tmp_path, capsys):
    """0.5 s: a duration whose float steps overshoot it (tqdm warned and clamped)."""
    import warnings

    camera = dataclasses.replace(SENSORS["davis240"], width=48, height=36, cx=23.5, cy=17.5, fx=40.0, fy=40.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate(SimConfig(duration_s=0.5, seed=1, camera=camera), tmp_path / "s", progress=True)
    shown = capsys.readouterr().err.replace("\r", "\n").strip().splitlines()
    assert re.search(r"100%\|.*\| 0\.50/0\.50 s simulated \[", shown[-1]), shown[-1]
    assert all(re.search(r"\d\.\d\d/0\.50 s simulated", line) for line in shown), shown
