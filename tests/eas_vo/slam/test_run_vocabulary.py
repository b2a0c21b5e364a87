"""`eas-vo slam`'s vocabulary, checked before ORB-SLAM3's child process starts: a broken file
(the user's, or the data folder's ORBvoc.txt) is one line naming its line, and ORB-SLAM3 never
loads it. Runs without the slam extra: the child is replaced by one that fails the test if started."""

import re

import numpy as np
import pytest

from eas_vo.slam import process
from eas_vo.slam import run as slam_run
from eas_vo.slam.vocabulary import train
from helpers import one_line_failure


@pytest.fixture
def no_child(monkeypatch):
    """pyorbslam3 reported installed, and ORB-SLAM3's process never started."""
    real = process.importlib.util.find_spec
    monkeypatch.setattr(
        process.importlib.util, "find_spec", lambda name, *a: object() if name == "pyorbslam3" else real(name, *a)
    )

    def started(*args, **kwargs):
        raise AssertionError("ORB-SLAM3 was started on a broken vocabulary")

    monkeypatch.setattr(slam_run, "OrbSlam3Process", started)


@pytest.fixture(scope="module")
def vocabulary_text():
    rng = np.random.default_rng(3)
    return train([rng.integers(0, 256, (100, 32), dtype=np.uint8) for _ in range(3)], k=4, levels=2, seed=0).text()


#: Broken copies of a vocabulary and the line each is refused at: descriptors of 64 bytes, a
#: byte above 255, a NaN weight, the file cut in half at a line's end.
BROKEN = {
    "64_bytes": (lambda lines: lines[:2] + ["0 0 " + "1 " * 64 + "0"] + lines[3:], 3),
    "byte_256": (lambda lines: lines[:3] + ["0 0 " + "256 " * 32 + "0"] + lines[4:], 4),
    "nan_weight": (lambda lines: lines[:-1] + [lines[-1].rsplit(" ", 1)[0] + " nan"], "last"),
    "half": (lambda lines: lines[: len(lines) // 2], r"\d+"),
}


@pytest.mark.parametrize("name", BROKEN)
@pytest.mark.parametrize("where", ["given", "data_folder"])
def test_a_broken_vocabulary_never_reaches_orbslam3(
    short_sequence, vocabulary_text, tmp_path, capsys, monkeypatch, no_child, name, where
):
    damage, line = BROKEN[name]
    lines = damage(vocabulary_text.split("\n"))
    line = len(lines) if line == "last" else line
    data = tmp_path / "data"
    data.mkdir()
    path = (tmp_path / "bad.txt") if where == "given" else data / "ORBvoc.txt"
    path.write_text("\n".join(lines))
    monkeypatch.delenv("PYORBSLAM3_VOCAB", raising=False)
    monkeypatch.setenv("EAS_VO_DATA_DIR", str(data))
    given = ["--vocabulary", str(path)] if where == "given" else []
    err = one_line_failure(["slam", "--dataset", str(short_sequence), *given, "--out", str(tmp_path / "out")], capsys)
    assert re.match(rf"eas-vo: error: {re.escape(str(path))}:{line}: ", err) and not (tmp_path / "out").exists()
