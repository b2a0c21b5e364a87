"""ORB statistics (the paper's Table 2) on known-answer image pairs."""

import cv2
import numpy as np

from eas_vo.orb import OrbStats


def textured_image(seed=0, size=(180, 240)):
    rng = np.random.default_rng(seed)
    image = np.full(size, 60, np.uint8)
    for _ in range(150):
        x, y, r = int(rng.integers(0, size[1])), int(rng.integers(0, size[0])), int(rng.integers(3, 12))
        cv2.rectangle(image, (x - r, y - r), (x + r, y + r // 2), int(rng.integers(0, 256)), -1)
    return image


def orb_keypoints(image) -> int:
    return len(cv2.ORB_create(nfeatures=1000).detect(image, None))


def test_an_image_matched_with_itself_matches_every_keypoint():
    image = textured_image()
    stats = OrbStats()
    stats.add(image)
    stats.add(image)
    n = orb_keypoints(image)
    assert n > 100
    assert stats.keypoints == [n, n] and stats.matches == [n]
    assert stats.summary() == {"orb_keypoints_mean": float(n), "orb_matches_mean": float(n)}


def test_a_blank_image_has_no_keypoints_and_no_matches():
    image = textured_image(1)
    stats = OrbStats()
    for frame in (image, np.zeros_like(image), image):
        stats.add(frame)
    n = orb_keypoints(image)
    assert stats.keypoints == [n, 0, n] and stats.matches == [0, 0]
    assert stats.summary()["orb_keypoints_mean"] == 2 * n / 3


def test_a_shifted_view_keeps_most_matches_and_an_unrelated_one_fewer():
    image = textured_image(2, (220, 280))
    a, shifted, other = image[:180, :240], image[9:189, 13:253], textured_image(3)
    stats = OrbStats()
    for frame in (a, shifted, other):
        stats.add(frame)
    overlap = orb_keypoints(image[9:180, 13:240])
    assert stats.matches[0] >= 0.7 * overlap  # cross-checked matches between the two views
    # unrelated images still get mutual nearest neighbours (Table 2 counts matches, not inliers)
    assert stats.matches[1] < 0.75 * stats.matches[0]
