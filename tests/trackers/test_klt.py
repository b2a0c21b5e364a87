"""The paper's tracker on frames warped by known rotations, its threshold logic, and its
results taken late (the next frame tracked meanwhile) equal to its results taken at once."""

import dataclasses
import functools
import re
import typing

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo import concurrency
from eas_vo.camera import CameraModel
from eas_vo.errors import ConfigError
from eas_vo.trackers.klt import KltConfig, KltTracker
from eas_vo.trackers.measurement import predicted_error_px
from eas_vo.types import ImuSeries
from helpers import CAMERA, K, assert_rotations_close, large_rotation, textured_image, warp_by_rotation


@pytest.mark.parametrize("seed", range(6))
def test_recovers_known_rotations_to_0_2_degrees_per_frame(seed):
    rng = np.random.default_rng(100 + seed)
    base = textured_image(seed)
    tracker = KltTracker(KltConfig(), CAMERA)
    tracker.process(base, 0.0)
    R_c0_ck = np.eye(3)
    for k in range(1, 5):
        step = Rotation.from_rotvec(rng.normal(0, 0.012, 3)).as_matrix()  # ~1 degree per frame
        R_c0_ck = R_c0_ck @ step
        image = warp_by_rotation(base, R_c0_ck.T)
        record, edges = tracker.process(image, k * 0.05)
        assert record.status == "ok" and len(edges) == 1, record
        (edge,) = edges
        assert (edge.i, edge.j) == (k - 1, k)
        assert_rotations_close(edge.R_i_j, step, np.radians(0.2))
        assert record.inliers <= record.nc


def test_featureless_frames_keep_the_previous_rotation_and_trigger_redetection():
    tracker = KltTracker(KltConfig(threshold1=10, threshold2=50), CAMERA)
    record, edges = tracker.process(np.zeros((180, 240), np.uint8), 0.0)
    assert record.status == "first" and edges == []
    record, edges = tracker.process(np.zeros((180, 240), np.uint8), 0.05)
    assert (record.status, record.reason, record.nc, edges, record.redetected) == (
        "lost",
        "few correspondences",
        0,
        [],
        True,
    )


def test_threshold2_controls_redetection():
    base = textured_image(1)
    shifted = warp_by_rotation(base, Rotation.from_rotvec([0, 0.01, 0]).as_matrix())
    for threshold2, expected in ((10, False), (100_000, True)):
        tracker = KltTracker(KltConfig(threshold1=10, threshold2=threshold2), CAMERA)
        tracker.process(base, 0.0)
        record, _ = tracker.process(shifted, 0.05)
        assert record.nc >= 10 and record.redetected is expected


def test_threshold1_above_nc_keeps_the_previous_rotation():
    base = textured_image(2)
    shifted = warp_by_rotation(base, Rotation.from_rotvec([0.01, 0, 0]).as_matrix())
    tracker = KltTracker(KltConfig(threshold1=100_000, threshold2=100_000), CAMERA)
    tracker.process(base, 0.0)
    record, edges = tracker.process(shifted, 0.05)
    assert record.nc > 20 and (record.status, record.reason) == ("lost", "few correspondences") and edges == []


def test_distortion_is_removed_before_geometry():
    """Points observed through a distorting lens give the same rotation as undistorted ones."""
    from eas_vo.geometry.two_view import rotation_from_correspondences

    rng = np.random.default_rng(5)
    dist = np.array([-0.3, 0.1, 0.0, 0.0, 0.0])
    camera = CameraModel(240, 180, K, dist)
    bearings = np.column_stack([rng.uniform(-0.5, 0.5, (200, 2)), np.ones(200)])
    R_c1_c0 = Rotation.from_rotvec([0.01, -0.02, 0.015]).as_matrix()
    t_c1 = np.array([0.02, 0.0, 0.01])
    X = bearings * rng.uniform(2, 5, (200, 1))
    X1 = X @ R_c1_c0.T + t_c1
    px0 = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)[0].reshape(-1, 2)
    px1 = cv2.projectPoints(X1, np.zeros(3), np.zeros(3), K, dist)[0].reshape(-1, 2)
    R = rotation_from_correspondences(camera.undistort(px0), camera.undistort(px1), 1e-3, 0.999).R_prev_cur
    assert_rotations_close(R, R_c1_c0.T, 1e-5)
    naive = CameraModel(240, 180, K)
    R_naive = rotation_from_correspondences(naive.undistort(px0), naive.undistort(px1), 1e-3, 0.999).R_prev_cur
    assert np.degrees(float(np.arccos((np.trace(R_naive.T @ R_c1_c0.T) - 1) / 2))) > 0.05


def test_keyframe_edges_measure_rotation_across_several_frames():
    rng = np.random.default_rng(7)
    base = textured_image(3)
    tracker = KltTracker(KltConfig(keyframe_interval=3, threshold2=10), CAMERA)
    tracker.process(base, 0.0)
    R_c0 = [np.eye(3)]
    spans = []
    for k in range(1, 8):
        R_c0.append(R_c0[-1] @ Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix())
        _, edges = tracker.process(warp_by_rotation(base, R_c0[k].T), k * 0.05)
        for e in edges:
            assert_rotations_close(e.R_i_j, R_c0[e.i].T @ R_c0[e.j], np.radians(0.2))
            spans.append((e.i, e.j))
    assert (0, 2) in spans and (0, 3) in spans and (3, 5) in spans and (3, 6) in spans
    assert all(j - i <= 3 for i, j in spans)


# ----------------------------------------------------------------------------- fast motion


def big_pair(seed):
    base = textured_image(seed, shapes=300)
    R_c0_c1 = large_rotation(np.random.default_rng(100 + seed))
    return base, R_c0_c1


@pytest.mark.parametrize("seed", range(4))
def test_gyro_prediction_lets_lk_follow_a_large_rotation(seed):
    """The gyro turned by R_c0_c1 over the frame interval; LK starts from K R K^-1."""
    from eas_vo.types import ImuSeries

    base, R_c0_c1 = big_pair(seed)
    t_imu = np.linspace(-0.1, 0.2, 61)
    omega = np.tile(Rotation.from_matrix(R_c0_c1).as_rotvec() / 0.05, (len(t_imu), 1))
    imu = ImuSeries(t_imu, np.zeros_like(omega), omega)
    tracker = KltTracker(KltConfig(predict="auto", fb_max_px=1.0), CAMERA, imu=imu)
    tracker.process(base, 0.0)
    record, (edge,) = tracker.process(warp_by_rotation(base, R_c0_c1.T), 0.05)
    assert record.status == "ok" and record.inlier_ratio > 0.8
    assert_rotations_close(edge.R_i_j, R_c0_c1, np.radians(0.2))


@pytest.mark.parametrize("seed", range(3))
def test_constant_velocity_prediction_bridges_a_long_gap(seed):
    """A 2-degree step in 50 ms, then ten times as long at the same angular velocity (20 degrees)."""
    base, _ = big_pair(seed)
    rotvec = np.random.default_rng(seed).normal(size=3)
    rotvec *= np.radians(2.0) / np.linalg.norm(rotvec)
    step = Rotation.from_rotvec(rotvec).as_matrix()
    R_c0_c2 = step @ Rotation.from_rotvec(10 * rotvec).as_matrix()
    tracker = KltTracker(KltConfig(predict="velocity", fb_max_px=1.0), CAMERA)
    tracker.process(base, 0.0)
    tracker.process(warp_by_rotation(base, step.T), 0.05)
    record, (edge,) = tracker.process(warp_by_rotation(base, R_c0_c2.T), 0.55)
    assert record.status == "ok"
    assert_rotations_close(edge.R_i_j, Rotation.from_rotvec(10 * rotvec).as_matrix(), np.radians(0.2))


@pytest.mark.parametrize("detector", ["orb", "sift"])
@pytest.mark.parametrize("seed", range(3))
def test_descriptor_fallback_rescues_a_lost_track(seed, detector):
    base, R_c0_c1 = big_pair(seed)
    tracker = KltTracker(KltConfig(fallback="match", fallback_detector=detector), CAMERA)
    tracker.process(base, 0.0)
    record, (edge,) = tracker.process(warp_by_rotation(base, R_c0_c1.T), 0.05)
    assert record.status == "ok" and record.redetected
    assert_rotations_close(edge.R_i_j, R_c0_c1, np.radians(0.2))
    small = Rotation.from_rotvec([0.0, 0.01, 0.0]).as_matrix()  # and LK carries on from the new corners
    record, (edge,) = tracker.process(warp_by_rotation(base, (R_c0_c1 @ small).T), 0.1)
    assert record.status == "ok"
    assert_rotations_close(edge.R_i_j, small, np.radians(0.2))


def test_prediction_options_are_checked():
    with pytest.raises(ConfigError, match="predict = 'psychic'; allowed: none, gyro, velocity, auto"):
        KltConfig(predict="psychic").validate()


def test_lk_stops_where_configured():
    """lk_max_iterations and lk_epsilon_px reach OpenCV's termination criteria; nonsense is refused."""
    tracker = KltTracker(KltConfig(lk_max_iterations=10, lk_epsilon_px=0.03), CAMERA)
    assert tracker._lk_params["criteria"][1:] == (10, 0.03)
    assert KltTracker(KltConfig(), CAMERA)._lk_params["criteria"][1:] == (30, 0.01)  # OpenCV's defaults: the paper
    for key, value in (("lk_max_iterations", 0), ("lk_epsilon_px", 0.0)):
        with pytest.raises(ConfigError, match=key):
            KltConfig(**{key: value}).validate()


def copied(camera: CameraModel, n: int) -> CameraModel:
    """`camera` for its images copied pixel for pixel n times larger (the same lens and view)."""
    pixel_centres_kept = np.array([[n, 0, 0.5 * (n - 1)], [0, n, 0.5 * (n - 1)], [0, 0, 1]])
    return CameraModel(camera.width * n, camera.height * n, pixel_centres_kept @ camera.K, camera.dist)


@pytest.mark.parametrize("seed", [1, 5])
def test_the_same_views_through_more_pixels_are_tracked_alike(seed):
    """An 11-13 degree step (40 px at 240x180), and the same two images copied pixel for pixel
    at 480x360 and 960x720: the corner spacing, windows and pyramid follow the focal length
    (whole octaves: one and two pyramid levels more), so the copies measure the step as
    240x180 does: most corners inliers, within 0.15 degree, and at 480x360 the error its
    covariance predicts [px of focal length], which the frame status reads, within 1.5 times
    240x180's (the 4x copy's blocks double LK's noise in pixels, which its covariance sees). With them
    fixed in pixels the copies' pyramid reaches a half and a quarter as far in angle: inlier
    ratios of 0.17-0.41."""
    rng = np.random.default_rng(300 + seed)
    step = Rotation.from_rotvec(rng.normal(0, 0.09, 3)).as_matrix()
    first = textured_image(seed)
    second = warp_by_rotation(first, step.T)
    predicted = {}
    for n in (1, 2, 4):
        camera = copied(CAMERA, n)
        tracker = KltTracker(KltConfig(), camera)
        tracker.process(np.repeat(np.repeat(first, n, 0), n, 1), 0.0)
        record, edges = tracker.process(np.repeat(np.repeat(second, n, 0), n, 1), 0.05)
        assert record.inlier_ratio > 0.5, (n, record)
        predicted[n] = predicted_error_px(edges[0], camera.focal_px)
        assert_rotations_close(edges[0].R_i_j, step, np.radians(0.15 if n > 1 else 0.4))
    assert 1 / 1.5 < predicted[2] / predicted[1] < 1.5, predicted  # the same status bound on every sensor


# ----------------------------------------------------------------------------- threads


@functools.cache
def turning_sequence() -> tuple[list[float], list[np.ndarray], ImuSeries]:
    """Times [s], images and the gyro (camera frame) of 30 frames: a pan out at 1.5 deg a frame,
    then after a gap of three frame intervals a turn of 25 deg that LK loses and either fallback
    measures, then back to the first view in 18 steps (where a loop closes with frame 0)."""
    out = Rotation.from_rotvec(np.radians([0.3, 1.5, 0.2]))
    turn = Rotation.from_rotvec(np.radians([12.0, -18.0, -12.0]))
    R_c0_c11 = Rotation.from_rotvec(10 * out.as_rotvec()) * turn
    back = Rotation.from_rotvec(-R_c0_c11.as_rotvec() / 18)
    steps = [(out, 0.05)] * 10 + [(turn, 0.15)] + [(back, 0.05)] * 18  # (R_{k-1}_{k}, interval [s])
    base = textured_image(4, shapes=300)
    times, images, R_c0_ck = [0.0], [base], Rotation.identity()
    for step, dt_s in steps:
        R_c0_ck = R_c0_ck * step
        times.append(times[-1] + dt_s)
        images.append(warp_by_rotation(base, R_c0_ck.as_matrix().T))
    t_imu = np.arange(0.0, times[-1] + 0.01, 0.005)
    interval = np.clip(np.searchsorted(times, t_imu, side="right") - 1, 0, len(steps) - 1)
    rates = np.array([step.as_rotvec() / dt_s for step, dt_s in steps])[interval]
    return times, images, ImuSeries(t_imu, np.zeros_like(rates), rates)


def allowed_values(name: str) -> list[str]:
    """The values KltConfig's validation allows for its text field `name`."""
    try:
        dataclasses.replace(KltConfig(), **{name: ""}).validate()
    except ConfigError as refused:
        allowed = re.fullmatch(rf"{name} = ''; allowed: (.+)", str(refused))
        if allowed:
            return allowed.group(1).split(", ")
    raise AssertionError(f"KltConfig.{name} is text but not a choice: give the thread test its values")


def choices() -> list[tuple[str, object]]:
    """(field, value): every value of every choice field of KltConfig (a bool's both, a text
    field's every allowed value), so a new option is tried without being listed here."""
    types = typing.get_type_hints(KltConfig)
    return [
        (f.name, value)
        for f in dataclasses.fields(KltConfig)
        for value in (
            (False, True) if types[f.name] is bool else allowed_values(f.name) if types[f.name] is str else ()
        )
    ]


#: What a choice needs switched on to act at all: its values are tried with these set.
ENABLED_BY = {
    "fallback_detector": {"fallback": "match"},
    "loop_detector": {"loop_closure": True},
    "loop_geometry": {"loop_closure": True},
}


@functools.cache
def tracked(config: KltConfig, threads: int) -> tuple:
    """The turning sequence's (record, edges as bytes) per frame and the tracker's warnings: with
    one thread, each frame's result taken at once (`process`, as the run with --threads 1);
    with more, each taken after the next frame was submitted (as the run with --threads 2)."""
    times, images, imu = turning_sequence()
    before = concurrency.threads()
    concurrency.set_threads(threads)
    try:
        tracker = KltTracker(config, CAMERA, imu=imu)
        if threads == 1:
            results = [tracker.process(image, t) for t, image in zip(times, images)]
        else:
            results, pending = [], None
            for t, image in zip(times, images):
                submitted = tracker.submit(image, t)
                if pending is not None:
                    results.append(pending())
                pending = submitted
            results.append(pending())
    finally:
        concurrency.set_threads(before)
    return tuple(
        (record, tuple(repr(dataclasses.replace(e, R_i_j=e.R_i_j.tobytes())) for e in edges))
        for record, edges in results
    ), tracker.tracker_warnings


@pytest.mark.parametrize("field, value", choices(), ids=lambda value: str(value))
def test_results_taken_late_equal_those_taken_at_once(field, value):
    """Whatever a choice field says, a frame finished while the next one is tracked gives what
    the serial path gives, to the bit: what the next frame's tracking reads of it is there."""
    config = dataclasses.replace(KltConfig(), **{**ENABLED_BY.get(field, {}), field: value})
    config.validate()
    assert tracked(config, 2) == tracked(config, 1)


def test_the_thread_tests_sequence_exercises_the_options():
    """LK loses the turn (frame 11), which either fallback measures; a loop closes; each
    prediction changes what is measured."""

    def frame(config: KltConfig, k: int):
        return tracked(config, 1)[0][k]

    assert frame(KltConfig(), 11)[0].status == "lost"
    for fallback in ("match", "align"):
        record, edges = frame(KltConfig(fallback=fallback), 11)
        assert record.status == "ok" and record.redetected and len(edges) == 1, fallback
    frames, _ = tracked(KltConfig(loop_closure=True), 1)
    assert any("loop=True" in edge for _, edges in frames for edge in edges)
    paper = tracked(KltConfig(), 1)
    assert all(tracked(KltConfig(predict=predict), 1) != paper for predict in ("gyro", "velocity"))
