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
    default = RosbagDataset(tmp_path / "custom.bag")  # default topics: no frames, no events
    assert len(default.events()) == 0 and default.load_frame(0) is None


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
    with pytest.raises(DataError, match=r"damaged.bag:/dvs/events:3: cannot decode event array"):
        RosbagDataset(dst).events()
    lenient = RosbagDataset(dst, BagConfig(lenient=True))
    assert len(lenient.events()) == len(sequence.events()) - 5000
    assert "1 dropped: undecodable event array (first at message 3)" in lenient.warnings.lines()[0]



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
