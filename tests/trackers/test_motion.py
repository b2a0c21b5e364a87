"""LK started from a predicted rotation, on cameras whose lens distorts: the derotation of the
previous image and of its points goes through the lens model, built here by OpenCV's own lens
functions (cv2.fisheye for the equidistant model)."""

import cv2
import numpy as np
import pytest

from eas_vo.trackers.motion import lk_params, lk_track
from helpers import ECD_DAVIS240, MVSEC_LEFT, opencv_rotated, textured_image


@pytest.mark.parametrize("camera", [MVSEC_LEFT, ECD_DAVIS240], ids=["equidistant", "radtan"])
def test_lk_from_a_predicted_rotation_lands_on_the_true_points_through_the_lens(camera):
    source = textured_image(3, size=(camera.height, camera.width), shapes=int(camera.width * camera.height / 360))
    R_source_image = cv2.Rodrigues(np.radians([4.0, -7.0, 12.0]))[0]  # 14 deg, most of it roll
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    where = opencv_rotated(camera, R_source_image, np.column_stack([u.ravel(), v.ravel()])).astype(np.float32)
    image = cv2.remap(
        source, where[:, 0].reshape(u.shape), where[:, 1].reshape(u.shape), cv2.INTER_LINEAR, borderValue=60
    )
    corners = cv2.goodFeaturesToTrack(source, 400, 0.01, 7, blockSize=3).reshape(-1, 2)
    truth = opencv_rotated(camera, R_source_image.T, corners)
    margin = 12  # corners whose patch stays whole in the image
    inside = ((truth >= margin) & (truth < [camera.width - margin, camera.height - margin])).all(axis=1)
    corners, truth = corners[inside], truth[inside]
    centre = camera.K[:2, 2]
    periphery = np.linalg.norm(truth - centre, axis=1) > 0.5 * np.linalg.norm(centre)
    assert periphery.sum() >= 15

    # One pyramid level: LK reaches a few pixels, so only a prediction through the lens gets there.
    cur, ok = lk_track(camera, source, corners, image, lk_params(max_level=0), R_source_image)
    error = np.linalg.norm(cur - truth, axis=1)
    assert ok.mean() > 0.9 and ok[periphery].mean() > 0.9
    assert np.median(error[ok]) < 0.05 and np.median(error[ok & periphery]) < 0.05

    # What the pinhole homography K R^T K^-1 would have predicted there: pixels off.
    H = camera.K @ R_source_image.T @ np.linalg.inv(camera.K)
    pinhole = cv2.perspectiveTransform(corners.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
    assert np.median(np.linalg.norm(pinhole - truth, axis=1)[periphery]) > 2.0
