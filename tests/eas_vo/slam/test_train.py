"""`eas-vo vocabulary`: ORB descriptors with ORB-SLAM's extractor settings, and a tree DBoW2
cannot load refused before any image is read."""

import numpy as np

from eas_vo.slam import train as train_mod
from helpers import one_line_failure, textured_image


def test_descriptors_are_orbs_32_bytes_and_an_empty_image_gives_none():
    descriptors = train_mod.orb_descriptors(textured_image(seed=1))
    assert descriptors.dtype == np.uint8 and descriptors.shape[1] == 32 and 100 < len(descriptors) <= 1000
    assert train_mod.orb_descriptors(np.zeros((180, 240), np.uint8)).shape == (0, 32)


def test_a_tree_dbow2_refuses_is_one_line_before_any_image_is_read(short_sequence, tmp_path, capsys, monkeypatch):
    def no_reading(config):
        raise AssertionError("the dataset was opened")

    monkeypatch.setattr("eas_vo.pipeline.open_pipeline", no_reading)
    err = one_line_failure(
        ["vocabulary", "--dataset", str(short_sequence), "--k", "21", "--out", str(tmp_path / "v.txt")], capsys
    )
    assert "DBoW2 takes k in 2..20" in err and not (tmp_path / "v.txt").exists()
