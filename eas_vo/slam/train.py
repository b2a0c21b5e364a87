"""`eas-vo vocabulary`: a DBoW2 vocabulary trained on the ORB descriptors of a sequence's own
images (a frontend's), for ORB-SLAM3 offline and in the tests."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from eas_vo.io.atomic import atomic_path
from eas_vo.slam.vocabulary import DESCRIPTOR_BYTES, check_shape, train


def orb_descriptors(image: np.ndarray) -> np.ndarray:
    """ORB descriptors (n, 32) uint8 of one image with ORB-SLAM's extractor settings
    (orbslam.ORB_EXTRACTOR: features, scale factor, levels, FAST threshold) in OpenCV's ORB,
    whose rBRIEF test pattern ORB-SLAM's extractor shares."""
    from eas_vo.slam.export import ORB_EXTRACTOR

    orb = cv2.ORB_create(
        nfeatures=ORB_EXTRACTOR["nFeatures"],
        scaleFactor=ORB_EXTRACTOR["scaleFactor"],
        nlevels=ORB_EXTRACTOR["nLevels"],
        fastThreshold=ORB_EXTRACTOR["iniThFAST"],
    )
    _, descriptors = orb.detectAndCompute(image, None)
    return descriptors if descriptors is not None else np.empty((0, DESCRIPTOR_BYTES), np.uint8)


def train_vocabulary(config, out: str | Path, k: int, levels: int, seed: int = 0, progress: bool = False) -> dict:
    """Train on every image of the configured window and frontend; write the text vocabulary to
    `out` atomically. Returns what it holds (images, descriptors, nodes, words)."""
    from tqdm import tqdm

    from eas_vo.pipeline import open_pipeline
    from eas_vo.pipeline.tracking import check_image

    check_shape(k, levels)  # before any image is read
    rc = config.run
    parts = open_pipeline(config)
    window = parts.dataset.window(rc.start_s, rc.duration_s)
    sets = []
    for sample in tqdm(
        parts.dataset.samples(rc.start_s, rc.duration_s),
        total=len(window),
        disable=not progress,
        unit="frame",
        desc=f"ORB descriptors of {rc.frontend}",
    ):
        image = parts.frontend(sample)
        check_image(image, parts.dataset.camera, rc.frontend, sample)
        sets.append(orb_descriptors(image))
    vocabulary = train(sets, k, levels, seed)
    with atomic_path(out) as tmp:
        Path(tmp).write_text(vocabulary.text())
    return {
        "images": len(sets),
        "descriptors": int(sum(len(d) for d in sets)),
        "nodes": len(vocabulary.parent) - 1,
        "words": vocabulary.words,
        "dataset": parts.dataset.label,
        "frontend": rc.frontend,
    }
