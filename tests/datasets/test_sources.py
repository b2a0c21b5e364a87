"""One sequence through three doors: extracted folder, .zip read in place, ROS1 bag; and hostile
zip archives (hypothesis): a one-line error naming the archive, or exactly what it holds."""

import io
import zipfile

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.rosbag import write_bag
from eas_vo.errors import DataError
from eas_vo.eventfile import convert_text_to_cache
from eas_vo.registry import open_dataset
from eas_vo.types import EVENT_DTYPE
from helpers import hostile_settings


def make_zip(folder, path, prefix=""):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(folder.rglob("*")):
            if f.is_file():
                zf.write(f, prefix + str(f.relative_to(folder)))
    return path


@pytest.fixture(scope="module")
def doors(short_sequence, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("doors")
    folder = open_dataset(str(short_sequence))
    bag = tmp / "seq.bag"
    write_bag(folder, bag)
    return {
        "folder": folder,
        "zip": open_dataset(str(make_zip(short_sequence, tmp / "seq.zip"))),
        "zip_in_subfolder": open_dataset(str(make_zip(short_sequence, tmp / "nested.zip", prefix="shapes/"))),
        "bag": open_dataset(str(bag)),
    }


@pytest.mark.parametrize("door", ["zip", "zip_in_subfolder", "bag"])
def test_every_door_yields_identical_data(doors, door):
    ref, other = doors["folder"], doors[door]
    assert type(other).__name__ == ("RosbagDataset" if door == "bag" else "EcdFolderDataset")
    np.testing.assert_array_equal(other.events(), ref.events())
    np.testing.assert_array_equal(other.frame_times(), ref.frame_times())
    for k in range(len(ref.frame_times())):
        np.testing.assert_array_equal(other.load_frame(k), ref.load_frame(k))
    for field in ("t", "p_w_c", "q_w_c"):
        np.testing.assert_array_equal(getattr(other.ground_truth, field), getattr(ref.ground_truth, field))
    for field in ("t", "acc", "gyro"):
        np.testing.assert_array_equal(getattr(other.imu, field), getattr(ref.imu, field))
    np.testing.assert_array_equal(other.camera.K, ref.camera.K)
    np.testing.assert_array_equal(other.camera.dist, ref.camera.dist)


def test_pipeline_gives_the_same_result_through_every_door(doors):
    from eas_vo import config, pipeline

    results = {}
    for door in ("folder", "zip", "bag"):
        spec = doors[door].label
        cfg = config.resolve(None, {"dataset": spec, "frontend": "eas"})
        results[door] = pipeline.run(cfg).metrics
    assert results["zip"]["ape_mean_rad"] == results["folder"]["ape_mean_rad"] == results["bag"]["ape_mean_rad"]


def test_damaged_zip_entry_is_named(short_sequence, tmp_path):
    path = make_zip(short_sequence, tmp_path / "seq.zip")
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("events.txt")
    start = info.header_offset + 30 + len(info.filename) + 2000
    data[start : start + 64] = bytes(64)  # corrupt the compressed events
    path.write_bytes(bytes(data))
    with pytest.raises(DataError, match=r"seq.zip:events.txt"):
        EcdFolderDataset(path).events()


def test_a_zip_nesting_its_sequence_two_folders_deep_says_where_it_is(short_sequence, tmp_path):
    path = make_zip(short_sequence, tmp_path / "deep.zip", prefix="downloads/shapes/")
    with pytest.raises(DataError, match="deep.zip: holds its sequence in downloads/shapes/, more than one folder deep"):
        open_dataset(str(path))


def test_not_a_zip(tmp_path):
    (tmp_path / "x.zip").write_bytes(b"hello")
    with pytest.raises(DataError, match="x.zip: not a readable zip archive"):
        open_dataset(str(tmp_path / "x.zip"))


@hostile_settings()
@given(data=st.binary(max_size=400), cut=st.integers(0, 400))
def test_truncated_or_garbage_zip_is_named_or_read_whole(tmp_path_factory, short_sequence, data, cut):
    path = tmp_path_factory.mktemp("z") / "seq.zip"
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        for name in ("calib.txt", "images.txt", "events.txt"):
            zf.writestr(name, (short_sequence / name).read_bytes()[:2000] if name != "images.txt" else b"")
    blob = buffer.getvalue()
    path.write_bytes(blob[: len(blob) * cut // 400] + data)
    try:
        dataset = open_dataset(str(path))
        events = dataset.events()
    except DataError as exc:
        assert "\n" not in str(exc) and "seq.zip" in str(exc)
        return
    with zipfile.ZipFile(path) as zf:  # accepted: what was read is what the archive holds
        held, calib = zf.read("events.txt"), zf.read("calib.txt").split()
    expected = io.BytesIO()
    n = convert_text_to_cache(io.BytesIO(held), "events.txt", expected, 240, 180)
    assert len(events) == n and events.tobytes() == np.frombuffer(expected.getvalue(), EVENT_DTYPE).tobytes()
    np.testing.assert_array_equal(dataset.camera.calib_values()[: len(calib)], [float(v) for v in calib])


def test_a_zip_holding_two_sequences_is_refused(short_sequence, tmp_path):
    archive = tmp_path / "two.zip"
    with zipfile.ZipFile(archive, "w") as z:
        for top in ("a", "b"):
            for name in ("images.txt", "calib.txt"):
                z.write(short_sequence / name, f"{top}/{name}")
    with pytest.raises(DataError, match=r"two.zip: holds 2 sequences \(a, b\); a dataset archive must hold one"):
        EcdFolderDataset(archive)
