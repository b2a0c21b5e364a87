"""The paper's tracker on frames warped by known rotations, and its threshold logic."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers import assert_rotations_close
from eas_vo.trackers.klt import KltConfig, KltTracker
from eas_vo.types import CameraModel

K = np.array([[200.0, 0, 120], [0, 200.0, 90], [0, 0, 1]])
CAMERA = CameraModel(240, 180, K)


def textured_image(seed=0, size=(180, 240)):
    """Random rectangles and discs: plenty of corners."""
    rng = np.random.default_rng(seed)
    img = np.full(size, 60, np.uint8)
    for _ in range(120):
        x, y = rng.integers(0, size[1]), rng.integers(0, size[0])
        r = int(rng.integers(4, 14))
        colour = int(rng.integers(0, 256))
        if rng.random() < 0.5:
            cv2.rectangle(img, (x - r, y - r), (x + r, y + int(r * 0.7)), colour, -1)
        else:
            cv2.circle(img, (x, y), r, colour, -1)
    return cv2.GaussianBlur(img, (3, 3), 0.7)


def warp_by_rotation(img, R_c2_c1):
    """The view of a camera rotated by R_c1_c2 = R_c2_c1^T: x2 ~ K R_c2_c1 K^-1 x1 (infinite depth)."""
    H = K @ R_c2_c1 @ np.linalg.inv(K)
    return cv2.warpPerspective(img, H, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR, borderValue=60)


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
    assert (record.status, record.nc, edges, record.redetected) == ("few_correspondences", 0, [], True)


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
    assert record.nc > 20 and record.status == "few_correspondences" and edges == []


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
    R, _, _ = rotation_from_correspondences(camera.undistort(px0), camera.undistort(px1), 1e-3, 0.999)
    assert_rotations_close(R, R_c1_c0.T, 1e-5)
    naive = CameraModel(240, 180, K)
    R_naive, _, _ = rotation_from_correspondences(naive.undistort(px0), naive.undistort(px1), 1e-3, 0.999)
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
