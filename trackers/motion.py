"""Motion for trackers: the rotation between two frames predicted from the gyro or from a
constant angular velocity, and Lucas-Kanade tracking started from such a prediction on a
derotated image. Not a plugin."""

from __future__ import annotations

import cv2
import numpy as np

from eas_vo.camera import CameraModel


def lk_params(win_size: int = 21, max_level: int = 3, max_iterations: int = 30, epsilon_px: float = 0.01) -> dict:
    """Pyramidal Lucas-Kanade settings: window [px], pyramid levels, and when each level stops:
    after `max_iterations` or once a step is below `epsilon_px` [px] (OpenCV's defaults)."""
    return dict(
        winSize=(win_size, win_size),
        maxLevel=max_level,
        criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, max_iterations, epsilon_px),
    )


def lk_track(
    camera: CameraModel,
    source: np.ndarray,
    pts_px: np.ndarray,
    image: np.ndarray,
    params: dict,
    R_source_image: np.ndarray | None = None,
    fb_max_px: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """LK-track points `pts_px` of `source` into `image`: (N, 2) positions [px] and a mask of the
    tracked ones (inside the image; with `fb_max_px` > 0, back within that many pixels).

    With a predicted rotation R_source_image, `source` is first derotated into the view of
    `image` and each point is tracked from where that puts it: LK then only corrects the
    prediction's error, on patches no longer rotated against each other (a roll of 10 degrees
    otherwise biases it). The derotation goes through the lens model (CameraModel.rotation_maps);
    for a pinhole camera it is the homography K R_image_source K^-1, which is exact there."""
    if len(pts_px) == 0:
        return np.empty((0, 2), np.float32), np.zeros(0, bool)
    start = np.asarray(pts_px, np.float32).reshape(-1, 1, 2)
    if R_source_image is not None and camera.distorted:
        source = cv2.remap(source, *camera.rotation_maps(R_source_image), cv2.INTER_LINEAR)
        start = camera.rotated_pixels(R_source_image.T, start.reshape(-1, 2)).astype(np.float32).reshape(-1, 1, 2)
    elif R_source_image is not None:
        H = camera.K @ R_source_image.T @ np.linalg.inv(camera.K)
        source = cv2.warpPerspective(source, H, image.shape[::-1], flags=cv2.INTER_LINEAR)
        start = cv2.perspectiveTransform(start, H).astype(np.float32)
    cur, status, _ = cv2.calcOpticalFlowPyrLK(
        source, image, start, start.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params
    )
    h, w = image.shape
    ok = (
        (status.ravel() == 1)
        & (cur[:, 0, 0] >= 0)
        & (cur[:, 0, 0] <= w - 1)
        & (cur[:, 0, 1] >= 0)
        & (cur[:, 0, 1] <= h - 1)
    )
    if fb_max_px > 0:
        back, back_status, _ = cv2.calcOpticalFlowPyrLK(
            image, source, cur, start.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params
        )
        ok &= (back_status.ravel() == 1) & (np.linalg.norm((back - start).reshape(-1, 2), axis=1) <= fb_max_px)
    return cur.reshape(-1, 2), ok
