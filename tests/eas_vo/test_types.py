"""Core types: window lookups in an event stream, the gyro's rates between two times, the
camera model's lenses against OpenCV."""

import cv2
import numpy as np
import pytest

from eas_vo.camera import CameraModel
from helpers import ECD_DAVIS240, MVSEC_LEFT, opencv_rotated, random_events


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
    for t0, t1 in [
        (t[10], t[20]),
        (t[10] + 0.001, t[20] - 0.002),
        (t[0] - 0.02, t[3] + 0.001),
        (t[-3] - 0.001, t[-1] + 0.03),
    ]:
        rates, dt = imu.rates_between(t0, t1)
        np.testing.assert_allclose(turned(t1) - turned(t0), (rates * dt[:, None]).sum(axis=0), atol=1e-12)


def _sensor_pixels(camera: CameraModel) -> np.ndarray:
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    return np.stack([u.ravel(), v.ravel()], 1)


def test_equidistant_puts_a_ray_at_its_distorted_angle_from_the_axis():
    cam = MVSEC_LEFT
    theta = np.radians([0.0, 10.0, 30.0, 60.0, 100.0])  # 100 deg: behind the image plane, still mapped
    k1, k2, k3, k4 = cam.dist
    theta_d = theta * (1 + k1 * theta**2 + k2 * theta**4 + k3 * theta**6 + k4 * theta**8)
    rays = np.column_stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)])  # in the x-z plane
    np.testing.assert_allclose(
        cam.project(rays),
        np.column_stack([cam.K[0, 2] + cam.K[0, 0] * theta_d, np.full(5, cam.K[1, 2])]),
        rtol=0,
        atol=1e-9,
    )


def test_equidistant_equals_cv2_fisheye_over_the_whole_sensor():
    cam, px = MVSEC_LEFT, _sensor_pixels(MVSEC_LEFT)
    normalised = cam.undistort(px)
    reference = cv2.fisheye.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)
    np.testing.assert_allclose(cam.focal_px * normalised, cam.focal_px * reference, rtol=0, atol=1e-6)
    rays = np.column_stack([normalised, np.ones(len(px))])
    projected = cv2.fisheye.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)[0].reshape(
        -1, 2
    )
    np.testing.assert_allclose(cam.project(normalised), projected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(cam.project(normalised), px, rtol=0, atol=1e-6)  # the round trip
    np.testing.assert_allclose(
        cam.project(rays * np.linspace(0.1, 10, len(px))[:, None]), px, rtol=0, atol=1e-6
    )  # any ray length


def test_radtan_equals_cv2_project_points_and_undistort_points_over_the_whole_sensor():
    cam, px = ECD_DAVIS240, _sensor_pixels(ECD_DAVIS240)
    normalised = cam.undistort(px)
    np.testing.assert_array_equal(normalised, cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2))
    projected = cv2.projectPoints(
        np.column_stack([normalised, np.ones(len(px))]), np.zeros(3), np.zeros(3), cam.K, cam.dist
    )[0]
    np.testing.assert_allclose(cam.project(normalised), projected.reshape(-1, 2), rtol=0, atol=1e-6)
    # cv2.undistortPoints iterates 5 times: at this lens' corners it stops short by a few
    # hundredths of a pixel (which is why the equidistant round trip above is the stricter test).
    assert np.abs(cam.project(normalised) - px).max() < 0.05


@pytest.mark.parametrize("camera", [MVSEC_LEFT, ECD_DAVIS240], ids=["equidistant", "radtan"])
def test_undistortion_maps_equal_opencvs(camera):
    K_new = camera.K @ np.diag([0.7, 0.7, 1.0])  # a wider pinhole view than K
    size = (camera.width, camera.height)
    if camera.model == "equidistant":
        expected = cv2.fisheye.initUndistortRectifyMap(camera.K, camera.dist, np.eye(3), K_new, size, cv2.CV_32FC1)
    else:
        expected = cv2.initUndistortRectifyMap(camera.K, camera.dist, None, K_new, size, cv2.CV_32FC1)
    for ours, theirs in zip(camera.undistort_maps(K_new), expected):
        assert ours.shape == (camera.height, camera.width) and ours.dtype == np.float32
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-3)


ROTATION = cv2.Rodrigues(np.radians([3.0, -5.0, 8.0]))[0]


@pytest.mark.parametrize("camera", [MVSEC_LEFT, ECD_DAVIS240], ids=["equidistant", "radtan"])
def test_rotated_views_follow_the_lens_as_opencv_does(camera):
    px = _sensor_pixels(camera)[::37]
    np.testing.assert_allclose(
        camera.rotated_pixels(ROTATION, px), opencv_rotated(camera, ROTATION, px), rtol=0, atol=1e-6
    )
    map_x, map_y = camera.rotation_maps(ROTATION)  # each pixel of the rotated view, where it is in the other
    assert map_x.shape == (camera.height, camera.width) and map_x.dtype == np.float32
    expected = opencv_rotated(camera, ROTATION, _sensor_pixels(camera))
    np.testing.assert_allclose(np.column_stack([map_x.ravel(), map_y.ravel()]), expected, rtol=0, atol=1e-3)


def test_a_pinholes_rotated_view_is_the_homography():
    pinhole = CameraModel(240, 180, ECD_DAVIS240.K, np.zeros(5))
    ideal_fisheye = CameraModel(240, 180, ECD_DAVIS240.K, np.zeros(4), "equidistant")  # f theta: no pinhole
    assert not pinhole.distorted and ECD_DAVIS240.distorted and MVSEC_LEFT.distorted and ideal_fisheye.distorted
    px = _sensor_pixels(pinhole)
    H = pinhole.K @ ROTATION @ np.linalg.inv(pinhole.K)
    expected = cv2.perspectiveTransform(px.reshape(-1, 1, 2), H).reshape(-1, 2)
    np.testing.assert_allclose(pinhole.rotated_pixels(ROTATION, px), expected, rtol=0, atol=1e-9)


def test_a_ray_across_the_image_plane_projects_as_numpy_divides():
    with np.errstate(divide="ignore", invalid="ignore"):
        assert not np.isfinite(ECD_DAVIS240.project(np.array([[1.0, 0.0, 0.0]]))).all()  # z = 0: no exception


def test_a_ray_behind_a_radtan_camera_is_seen_nowhere():
    behind = cv2.Rodrigues(np.radians([0.0, 180.0, 0.0]))[0]  # the view looking backwards
    map_x, map_y = ECD_DAVIS240.rotation_maps(behind)
    assert (map_x == -1).all() and (map_y == -1).all()


@pytest.mark.parametrize("k1", [-0.2, -0.3, -0.6, -1.2])
def test_a_radtan_lens_folds_where_its_radius_stops_growing(k1):
    """r (1 + k1 r^2) peaks at r = 1 / sqrt(-3 k1), where it is 2/3 of that: a fold where the
    sensor's corner (150 px at f = 200 px) lies beyond it, none where it does not."""
    r = 1 / np.sqrt(-3 * k1)
    radius = 2 / 3 * r * 200.0
    camera = CameraModel(240, 180, np.array([[200.0, 0, 120], [0, 200.0, 90], [0, 0, 1]]), np.array([k1, 0, 0, 0, 0]))
    assert camera.fold() == (pytest.approx((radius, np.arctan(r), 150.0)) if radius < 150 else None)


def test_an_equidistant_lens_folds_where_its_angle_stops_growing_or_at_180_degrees():
    K = np.array([[200.0, 0, 120], [0, 200.0, 90], [0, 0, 1]])
    theta = 1 / np.sqrt(3 * 0.5)  # theta (1 - 0.5 theta^2) peaks there, at 2/3 of it
    assert CameraModel(240, 180, K, np.array([-0.5, 0, 0, 0]), "equidistant").fold() == pytest.approx(
        (2 / 3 * theta * 200, theta, 150.0)
    )
    assert CameraModel(240, 180, K, np.zeros(4), "equidistant").fold() is None
    tiny = np.array([[30.0, 0, 120], [0, 30.0, 90], [0, 0, 1]])  # corners 5 rad off the axis: past any ray
    assert CameraModel(240, 180, tiny, np.zeros(4), "equidistant").fold() == pytest.approx((np.pi * 30, np.pi, 150.0))
