"""One sequence through three doors: extracted folder, .zip read in place, ROS1 bag."""

import zipfile

import numpy as np
import pytest

from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.datasets.rosbag import BagConfig, RosbagDataset, write_bag
from eas_vo.errors import DataError
from eas_vo.pipeline import open_dataset


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
        spec = doors[door].description
        cfg = config.resolve(None, {"dataset": spec, "frontend": "eas"})
        results[door] = pipeline.run(cfg).metrics
    assert results["zip"]["ape_mean_rad"] == results["folder"]["ape_mean_rad"] == results["bag"]["ape_mean_rad"]


def test_bag_topics_are_configurable(doors, tmp_path):
    custom = BagConfig(events_topic="/cam/events", image_topic="/cam/image")
    write_bag(doors["folder"], tmp_path / "custom.bag", custom)
    ds = RosbagDataset(tmp_path / "custom.bag", custom)
    assert len(ds.events()) == len(doors["folder"].events()) and len(ds.frame_times()) == len(doors["folder"].frame_times())
    default = RosbagDataset(tmp_path / "custom.bag")  # default topics: no frames, no events
    assert len(default.events()) == 0 and default.load_frame(0) is None


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


def test_not_a_zip_or_bag(tmp_path):
    (tmp_path / "x.zip").write_bytes(b"hello")
    (tmp_path / "x.bag").write_bytes(b"hello")
    with pytest.raises(DataError, match="x.zip: not a readable zip archive"):
        open_dataset(str(tmp_path / "x.zip"))
    with pytest.raises(DataError, match="x.bag: not a readable ROS1 bag"):
        open_dataset(str(tmp_path / "x.bag"))


def test_bag_event_message_damage_names_topic_and_index(doors, tmp_path):
    from rosbags.rosbag1 import Reader, Writer

    from eas_vo.datasets.rosbag import typestore

    src = doors["bag"].path
    dst = tmp_path / "damaged.bag"
    with Reader(src) as reader, Writer(dst) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=typestore()) for c in reader.connections}
        n_events = 0
        for conn, t, raw in reader.messages():
            if conn.topic == "/dvs/events":
                if n_events == 3:
                    raw = raw[:-7]  # a truncated event array
                n_events += 1
            writer.write(conns[conn.id], t, raw)
    with pytest.raises(DataError, match=r"damaged.bag:/dvs/events:3: cannot decode event array"):
        RosbagDataset(dst).events()
    lenient = RosbagDataset(dst, BagConfig(lenient=True))
    assert len(lenient.events()) == len(doors["bag"].events()) - 5000
    assert "1 dropped: undecodable event array (first at message 3)" in lenient.warnings.lines()[0]
