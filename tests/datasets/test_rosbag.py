"""ROS1 bags: configurable topics, damaged messages named by topic and index, and hostile
bytes (hypothesis): a one-line error naming the bag, or the sequence it holds."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eas_vo.datasets.rosbag import BagConfig, RosbagDataset, write_bag
from eas_vo.errors import DataError
from eas_vo.registry import open_dataset


@pytest.fixture(scope="module")
def sequence(short_sequence):
    return open_dataset(str(short_sequence))


@pytest.fixture(scope="module")
def bag_path(sequence, tmp_path_factory):
    path = tmp_path_factory.mktemp("bag") / "seq.bag"
    write_bag(sequence, path)
    return path


def test_bag_topics_are_configurable(sequence, tmp_path):
    custom = BagConfig(events_topic="/cam/events", image_topic="/cam/image")
    write_bag(sequence, tmp_path / "custom.bag", custom)
    ds = RosbagDataset(tmp_path / "custom.bag", custom)
    assert len(ds.events()) == len(sequence.events()) and len(ds.frame_times()) == len(sequence.frame_times())
    # The default names are absent: each stream is the bag's one topic of its message type.
    default = RosbagDataset(tmp_path / "custom.bag")
    assert default.topic["events_topic"] == "/cam/events" and default.topic["image_topic"] == "/cam/image"
    assert len(default.events()) == len(sequence.events()) and len(default.frame_times()) == len(sequence.frame_times())
    # A topic the user names that the bag lacks is refused, listing what the bag holds.
    with pytest.raises(
        DataError,
        match=r"has no topic /wrong \(dataset.events_topic\); its .* topic: /cam/events \(--set dataset.events_topic=/cam/events\); "
        r"it holds .*/cam/events \(dvs_msgs/msg/EventArray\)",
    ):
        RosbagDataset(tmp_path / "custom.bag", BagConfig(events_topic="/wrong"))


def test_not_a_bag(tmp_path):
    (tmp_path / "x.bag").write_bytes(b"hello")
    with pytest.raises(DataError, match="x.bag: not a readable ROS1 bag"):
        open_dataset(str(tmp_path / "x.bag"))


def test_bag_event_message_damage_names_topic_and_index(bag_path, sequence, tmp_path):
    from rosbags.rosbag1 import Reader, Writer

    from eas_vo.datasets.rosbag import typestore

    src = bag_path
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
    with pytest.raises(DataError, match=r"damaged.bag:/dvs/events:3: cannot decode event message"):
        RosbagDataset(dst).events()
    lenient = RosbagDataset(dst, BagConfig(lenient=True))
    assert len(lenient.events()) == len(sequence.events()) - 5000
    assert "1 dropped: undecodable event message (first at message 3)" in lenient.warnings.lines()[0]


def _compressed_copy(src, dst, compression):
    from rosbags.rosbag1 import Reader, Writer

    from eas_vo.datasets.rosbag import typestore

    writer = Writer(dst)
    writer.set_compression(getattr(Writer.CompressionFormat, compression))
    with Reader(src) as reader, writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=typestore()) for c in reader.connections}
        for conn, t, raw in reader.messages():
            writer.write(conns[conn.id], t, raw)


# Bytes damaged inside a chunk, one per kind of error rosbags' reader raises on them: a record
# header's length (its ReaderError), the record's connection id (a KeyError), its time (a failed
# assert), and a compressed chunk (bz2's OSError, lz4's RuntimeError).
@pytest.mark.parametrize("damage", ["header_length", "connection", "time", "bz2", "lz4"])
def test_damaged_bytes_inside_a_chunk_name_the_topic_message_and_time(bag_path, tmp_path, damage):
    from rosbags.rosbag1 import Reader

    topic = "/dvs/imu" if damage in ("header_length", "connection", "time") else "/dvs/image_raw"
    src = bag_path
    if damage in ("bz2", "lz4"):
        src = tmp_path / f"{damage}.bag"
        _compressed_copy(bag_path, src, damage.upper())
    data = bytearray(src.read_bytes())
    with Reader(src) as reader:
        entries = reader.indexes[next(c.id for c in reader.connections if c.topic == topic)]
        if damage in ("bz2", "lz4"):  # the fourth chunk's stream header: its first image is the one named
            chunk_pos = sorted(reader.chunks)[3]
            index = next(k for k, e in enumerate(entries) if e.chunk_pos == chunk_pos)
            data[reader.chunks[chunk_pos].datapos] ^= 0xFF
        else:  # the sixth IMU message's record header
            index = 5
            record = reader.chunks[entries[index].chunk_pos].datapos + entries[index].offset
            field = {
                "header_length": (record, 4),
                "connection": (data.index(b"conn=", record) + 5, 4),
                "time": (data.index(b"time=", record) + 5, 4),
            }[damage]
            data[field[0] : field[0] + field[1]] = b"\xf0\xff\xff\x7f"
        t_s = entries[index].time / 1e9
    path = tmp_path / "damaged.bag"
    path.write_bytes(bytes(data))
    with pytest.raises(
        DataError,
        match=rf"damaged.bag:{topic}:{index}: damaged bag data, message unreadable at "
        rf"bag time {t_s:.6f} s",
    ) as info:
        RosbagDataset(path)
    assert "\n" not in str(info.value)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(cut=st.floats(0.0, 1.0), flip=st.integers(0, 10**9))
def test_truncated_or_damaged_bag_is_named_or_read_whole(bag_path, sequence, tmp_path_factory, cut, flip):
    whole = bag_path.read_bytes()
    data = bytearray(whole[: int(len(whole) * cut)])
    if data and flip % 2:
        data[flip % len(data)] ^= 0xFF
    path = tmp_path_factory.mktemp("b") / "seq.bag"
    path.write_bytes(bytes(data))
    try:
        dataset = open_dataset(str(path))
        events = dataset.events()
    except DataError as exc:
        assert "seq.bag" in str(exc) and "\n" not in str(exc)
        return
    # accepted: never more than the bag held; without a flipped bit, exactly a prefix of it
    assert len(events) <= len(sequence.events()) and len(dataset.frame_times()) <= len(sequence.frame_times())
    if not flip % 2:
        assert events.tobytes() == np.asarray(sequence.events()[: len(events)]).tobytes()


def test_a_fisheye_camera_info_is_read_back_as_written(short_sequence, tmp_path):
    import shutil

    from eas_vo.camera import CameraModel
    from eas_vo.datasets.ecd import CAMCHAIN, camchain_yaml

    fisheye = CameraModel(
        240,
        180,
        np.array([[150.5, 0.0, 120.25], [0.0, 150.75, 89.5], [0.0, 0.0, 1.0]]),
        np.array([-0.048, 0.0113, -0.0554, 0.0215]),
        "equidistant",
    )
    folder = tmp_path / "seq"
    shutil.copytree(short_sequence, folder, ignore=shutil.ignore_patterns("calib.txt"))
    (folder / CAMCHAIN).write_text(camchain_yaml(fisheye))
    write_bag(open_dataset(str(folder)), tmp_path / "fisheye.bag")
    camera = RosbagDataset(tmp_path / "fisheye.bag").camera
    assert camera.model == "equidistant"
    np.testing.assert_array_equal(camera.K, fisheye.K)
    np.testing.assert_array_equal(camera.dist, fisheye.dist)


def test_a_distortion_model_eas_vo_does_not_read_is_refused(bag_path, tmp_path):
    from rosbags.rosbag1 import Reader, Writer

    from eas_vo.datasets.rosbag import typestore

    damaged = tmp_path / "fov.bag"
    store = typestore()
    with Reader(bag_path) as reader, Writer(damaged) as writer:
        connections = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        for connection, timestamp, raw in reader.messages():
            if connection.msgtype == "sensor_msgs/msg/CameraInfo":
                msg = store.deserialize_ros1(raw, connection.msgtype)
                msg.distortion_model = "fov"
                raw = store.serialize_ros1(msg, connection.msgtype)
            writer.write(connections[connection.id], timestamp, raw)
    with pytest.raises(DataError, match=r"fov.bag:/dvs/camera_info:0: distortion_model: 'fov' is not read"):
        RosbagDataset(damaged)
