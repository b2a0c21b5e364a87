"""ROS 2 bags: the event codecs against rosbags' serialiser and known answers, a simulated
sequence written by rosbags' rosbag2 Writer read back equal to its ECD folder (both storages,
folder and lone file), `can_open`, and hostile input: truncated and damaged files (hypothesis),
renamed text, empty topics, wrong types, refused encodings, foreign definitions, times going back."""

import shutil

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.datasets.bags import BagConfig, decode_mono, encode_mono
from eas_vo.datasets.rosbag2 import (
    DVS_ARRAY,
    PACKET_TYPES,
    Rosbag2Dataset,
    bag_typestore,
    decode_dvs_array,
    encode_dvs_array,
    event_typestore,
    write_bag2,
)
from eas_vo.errors import DataError
from eas_vo.registry import open_dataset, resolve_dataset
from eas_vo.types import ImuSeries, PoseSeries
from helpers import InMemoryDataset, hostile_settings, random_events, run_eas_vo

STORAGES = {"sqlite3": "db3", "mcap": "mcap"}


class Excerpt(InMemoryDataset):
    """The first `n_frames` frames of a dataset, with its events, IMU and poses until the last."""

    def __init__(self, dataset, n_frames: int):
        times = dataset.frame_times()[:n_frames]
        end = times[-1]
        events = dataset.events()
        imu, gt = dataset.imu, dataset.ground_truth
        super().__init__(
            dataset.camera,
            times,
            [dataset.load_frame(k) for k in range(n_frames)],
            np.asarray(events[events["t"] <= end]),
            ImuSeries(imu.t[imu.t <= end], imu.acc[imu.t <= end], imu.gyro[imu.t <= end]),
            PoseSeries(gt.t[gt.t <= end], gt.p_w_c[gt.t <= end], gt.q_w_c[gt.t <= end]),
        )


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """`eas-vo simulate --duration 1`, the ECD folder every bag here is made from."""
    folder = tmp_path_factory.mktemp("sim") / "one"
    result = run_eas_vo("simulate", "--out", str(folder), "--duration", "1")
    assert result.returncode == 0, result.stderr
    return folder


@pytest.fixture(scope="module")
def excerpt(simulated):
    return Excerpt(open_dataset(str(simulated)), 3)


@pytest.fixture(scope="module")
def small_bags(excerpt, tmp_path_factory):
    """{storage: rosbag2 folder} of the excerpt, events as dvs_msgs arrays of 2000."""
    root = tmp_path_factory.mktemp("bags")
    bags = {}
    for storage in STORAGES:
        bags[storage] = root / storage
        write_bag2(excerpt, bags[storage], storage, events_per_message=2000)
    return bags


def storage_file(folder, storage):
    return folder / f"{folder.name}.{STORAGES[storage]}"


# ----------------------------------------------------------------------------- codecs


@pytest.mark.parametrize("n", [0, 1, 2, 3, 57])
def test_dvs_array_bytes_are_rosbags_serialisation(n):
    """The numpy codec writes what rosbags' serialize_cdr writes (its CDR alignment: the first
    event 14 bytes, the later ones 16) and reads it back exactly."""
    store = event_typestore()
    T = store.types
    events = random_events(n, seed=n)
    ns = np.round(events["t"] * 1e9).astype(np.int64)
    time = T["builtin_interfaces/msg/Time"]
    msg = T[DVS_ARRAY](
        header=T["std_msgs/msg/Header"](stamp=time(sec=12, nanosec=34), frame_id="davis"),
        height=180,
        width=240,
        events=[
            T["dvs_msgs/msg/Event"](
                x=int(e["x"]),
                y=int(e["y"]),
                ts=time(sec=int(t // 10**9), nanosec=int(t % 10**9)),
                polarity=bool(e["p"]),
            )
            for e, t in zip(events, ns)
        ],
    )
    reference = bytes(store.serialize_cdr(msg, DVS_ARRAY))
    assert encode_dvs_array(12.000000034, 240, 180, events) == reference
    wire = decode_dvs_array(reference)
    assert np.array_equal(wire["x"], events["x"]) and np.array_equal(wire["y"], events["y"])
    assert np.array_equal(wire["sec"].astype(np.int64) * 10**9 + wire["nsec"], ns)
    assert np.array_equal(wire["p"], events["p"])
    with pytest.raises(ValueError, match=f"{n} events announced" if n else "bytes end within the message's header"):
        decode_dvs_array(reference[:-4] if n else reference[:-1])


def test_mono_known_answer():
    """event_camera_codecs' mono layout: time offset in bits 0-31, x 32-47, y 48-62, polarity 63."""
    words = np.array(
        [(1 << 63) | (200 << 48) | (300 << 32) | 123456, (0x7FFF << 48) | (0xFFFF << 32) | 0xFFFFFFFF, 0], "<u8"
    )
    t_ns, x, y, p = decode_mono(10**18, words.view(np.uint8))
    assert t_ns.tolist() == [10**18 + 123456, 10**18 + 2**32 - 1, 10**18]
    assert x.tolist() == [300, 0xFFFF, 0] and y.tolist() == [200, 0x7FFF, 0] and p.tolist() == [1, 0, 0]
    with pytest.raises(ValueError, match="not a multiple of 8"):
        decode_mono(0, np.zeros(12, np.uint8))


def test_mono_round_trip():
    events = random_events(1000, seed=4)
    events["t"] = 5.0 + events["t"] / 1000.0  # within 1.3 s of the time base
    base = 5_000_000_000
    t_ns, x, y, p = decode_mono(base, encode_mono(base, events))
    assert np.array_equal(t_ns, np.round(events["t"] * 1e9).astype(np.int64))
    assert np.array_equal(x, events["x"]) and np.array_equal(y, events["y"]) and np.array_equal(p, events["p"])


# ----------------------------------------------------------------------------- the same recording


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("encoding", ["dvs", "mono"])
def test_rosbag2_holds_the_ecd_folder(simulated, tmp_path, storage, encoding):
    """Written by rosbags' rosbag2 Writer, read back from the folder and from its lone storage
    file: events (integer nanoseconds), frames, IMU, ground truth and camera equal the folder's."""
    ecd = open_dataset(str(simulated))
    bag = tmp_path / "bag"
    write_bag2(ecd, bag, storage, encoding=encoding)
    for location in (bag, storage_file(bag, storage)):
        ds = open_dataset(str(location))
        assert isinstance(ds, Rosbag2Dataset)
        ev, ref = ds.events(), np.asarray(ecd.events())
        assert len(ev) == len(ref) > 100_000
        assert np.array_equal(np.round(ev["t"] * 1e9).astype(np.int64), np.round(ref["t"] * 1e9).astype(np.int64))
        assert ev.tobytes() == ref.tobytes()
        assert np.array_equal(ds.frame_times(), ecd.frame_times())
        assert all(np.array_equal(ds.load_frame(k), ecd.load_frame(k)) for k in range(len(ecd.frame_times())))
        for name in ("t", "acc", "gyro"):
            assert np.array_equal(getattr(ds.imu, name), getattr(ecd.imu, name))
        for name in ("t", "p_w_c", "q_w_c"):
            assert np.array_equal(getattr(ds.ground_truth, name), getattr(ecd.ground_truth, name))
        assert np.array_equal(ds.camera.K, ecd.camera.K) and np.array_equal(ds.camera.dist, ecd.camera.dist)
        assert (ds.camera.width, ds.camera.height) == (ecd.camera.width, ecd.camera.height)


@pytest.mark.parametrize("config", ["paper", "best"])
def test_paper_and_best_runs_give_the_same_trajectory_from_each_storage(simulated, tmp_path, config):
    ecd = open_dataset(str(simulated))
    sqlite_bag, mcap_bag = tmp_path / "sq", tmp_path / "mc"
    write_bag2(ecd, sqlite_bag, "sqlite3")
    write_bag2(ecd, mcap_bag, "mcap", encoding="mono")
    trajectories = []
    for n, location in enumerate((simulated, sqlite_bag, storage_file(mcap_bag, "mcap"))):
        out = tmp_path / f"run{n}"
        result = run_eas_vo("run", "--dataset", str(location), "--config", config, "--out", str(out))
        assert result.returncode == 0, result.stderr
        trajectories.append(np.loadtxt(out / "trajectory.tum"))
    assert len(trajectories[0]) == len(ecd.frame_times())
    for other in trajectories[1:]:
        assert other.shape == trajectories[0].shape
        assert np.abs(other - trajectories[0]).max() <= 1e-6


def test_equidistant_camera_and_custom_topics(excerpt, tmp_path):
    from eas_vo.camera import CameraModel

    fisheye = CameraModel(
        excerpt.camera.width,
        excerpt.camera.height,
        excerpt.camera.K,
        np.array([0.1, -0.02, 0.003, -0.0004]),
        model="equidistant",
    )
    excerpt_fisheye = Excerpt(excerpt, 3)
    excerpt_fisheye.camera = fisheye
    custom = BagConfig(events_topic="/cam/events", image_topic="/cam/image", camera_info_topic="/cam/info")
    write_bag2(excerpt_fisheye, tmp_path / "b", "mcap", custom)
    ds = Rosbag2Dataset(tmp_path / "b", custom)
    assert ds.camera.model == "equidistant" and np.array_equal(ds.camera.dist, fisheye.dist)
    assert len(ds.events()) == len(excerpt.events()) and len(ds.frame_times()) == 3
    found = Rosbag2Dataset(tmp_path / "b")  # the default names absent: the topics of each type
    assert np.array_equal(found.camera.dist, fisheye.dist) and len(found.frame_times()) == 3


# ----------------------------------------------------------------------------- can_open


def test_can_open_looks_at_the_header(small_bags, tmp_path):
    for storage, folder in small_bags.items():
        assert Rosbag2Dataset.can_open(str(folder)) and Rosbag2Dataset.can_open(str(storage_file(folder, storage)))
        assert resolve_dataset(str(folder))[0] is Rosbag2Dataset
    for name in ("notes.db3", "notes.mcap"):
        (tmp_path / name).write_text("SQLite format 2 and some notes\n")
        assert not Rosbag2Dataset.can_open(str(tmp_path / name))
        with pytest.raises(DataError, match=rf"{name}: not a ROS 2 bag file \(neither sqlite3 nor mcap\)$"):
            open_dataset(f"rosbag2:{tmp_path / name}")
    assert not Rosbag2Dataset.can_open(str(tmp_path))  # a folder without metadata.yaml
    assert not Rosbag2Dataset.can_open(str(tmp_path / "absent.db3"))
    with pytest.raises(DataError, match="a folder without metadata.yaml is not a rosbag2 bag"):
        Rosbag2Dataset(tmp_path)


@pytest.mark.parametrize("storage", sorted(STORAGES))
def test_metadata_that_names_no_storage_plugin_is_read_from_its_one_file(small_bags, excerpt, tmp_path, storage):
    """Older rosbag2 releases wrote `storage_identifier: ""` and an empty `files` list (version
    5): the folder is read from the one file its metadata names, as rosbag2 tells the storage
    by the file; what cannot be read so is one line saying what is wrong with the folder."""
    import yaml

    bag = shutil.copytree(small_bags[storage], tmp_path / "bag")
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info.update(version=5, storage_identifier="", files=[])
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    assert Rosbag2Dataset(bag).events().tobytes() == excerpt.events().tobytes()
    info["relative_file_paths"] = [*info["relative_file_paths"], "second.db3"]
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    with pytest.raises(
        DataError,
        match=r"metadata.yaml: names no storage plugin \(storage_identifier is empty\) and 2 bag "
        r"files: write the storage \(sqlite3 or mcap\) into it$",
    ):
        Rosbag2Dataset(bag)


def test_metadata_yaml_of_text_is_named(small_bags, tmp_path):
    bag = shutil.copytree(small_bags["sqlite3"], tmp_path / "bag")
    (bag / "metadata.yaml").write_text("these are my notes: [unclosed\n")
    with pytest.raises(DataError, match=r"bag: not a readable ROS 2 bag \(") as info:
        open_dataset(str(bag))
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------------------- hostile input


@hostile_settings(max_examples=30)
@given(
    storage=st.sampled_from(sorted(STORAGES)), cut=st.floats(0.0, 1.0), flip=st.integers(0, 10**9), lone=st.booleans()
)
def test_truncated_or_damaged_bag_is_named_or_read_within_bounds(
    small_bags, excerpt, tmp_path_factory, storage, cut, flip, lone
):
    """A bag cut at any offset, perhaps with one byte flipped: a one-line error naming it, or
    what it held (never more; unflipped, exactly its events)."""
    source = small_bags[storage]
    whole = storage_file(source, storage).read_bytes()
    data = bytearray(whole[: int(len(whole) * cut)])
    if data and flip % 2:
        data[flip % len(data)] ^= 0xFF
    folder = tmp_path_factory.mktemp("h") / source.name
    folder.mkdir()
    shutil.copy(source / "metadata.yaml", folder)
    storage_file(folder, storage).write_bytes(bytes(data))
    location = storage_file(folder, storage) if lone else folder
    try:
        ds = Rosbag2Dataset(location)
        events = ds.events()
    except DataError as exc:
        assert str(location) in str(exc) and "\n" not in str(exc)
        return
    assert len(events) <= len(excerpt.events()) and len(ds.frame_times()) <= len(excerpt.frame_times())
    if not flip % 2:
        assert bytes(data) == whole  # (a cut file never opens: sqlite and mcap both notice)
        assert events.tobytes() == excerpt.events().tobytes()


def _rewrite(src, dst, change):
    """Copy rosbag2 folder `src` to `dst` through rosbags, `change(topic, msgtype, index, raw)`
    giving (msgtype, raw) of each message (None drops it)."""
    from rosbags.rosbag2 import Reader, Writer

    store = event_typestore()
    with Reader(src) as reader, Writer(dst, version=9) as writer:
        connections, counts = {}, {}
        for conn, t, raw in reader.messages():
            index = counts[conn.topic] = counts.get(conn.topic, -1) + 1
            changed = change(conn.topic, conn.msgtype, index, bytes(raw))
            if changed is None:
                continue
            msgtype, raw = changed
            key = (conn.topic, msgtype)
            if key not in connections:
                connections[key] = writer.add_connection(conn.topic, msgtype, typestore=store)
            writer.write(connections[key], t, raw)


def test_damaged_event_message_named_and_dropped_when_lenient(small_bags, excerpt, tmp_path):
    def cut_fourth(topic, msgtype, index, raw):
        return msgtype, (raw[:-7] if topic == "/dvs/events" and index == 3 else raw)

    _rewrite(small_bags["sqlite3"], tmp_path / "bag", cut_fourth)
    with pytest.raises(DataError, match=r"bag:/dvs/events:3: cannot decode event message \(2000 events announced"):
        Rosbag2Dataset(tmp_path / "bag").events()
    lenient = Rosbag2Dataset(tmp_path / "bag", BagConfig(lenient=True))
    kept = np.concatenate([excerpt.events()[:6000], excerpt.events()[8000:]])
    assert lenient.events().tobytes() == kept.tobytes()
    assert lenient.data_warnings() == [
        f"{tmp_path / 'bag'}:/dvs/events: 1 dropped: undecodable event message (first at message 3)"
    ]


def test_mono_events_are_on_the_header_clock(small_bags, excerpt, tmp_path):
    """A packet's events are at its header stamp + dt (ROS time, the other topics' clock), not at
    time_base + dt (the camera's clock, here 1000 s off)."""
    from eas_vo.types import EVENT_DTYPE

    store = event_typestore()
    T = store.types

    def as_mono(topic, msgtype, index, raw):
        if topic != "/dvs/events":
            return msgtype, raw
        wire = decode_dvs_array(raw)
        events = np.empty(len(wire), EVENT_DTYPE)
        events["t"] = (wire["sec"].astype(np.int64) * 10**9 + wire["nsec"]) / 1e9
        events["x"], events["y"], events["p"] = wire["x"], wire["y"], wire["p"]
        first_ns = int(wire["sec"][0]) * 10**9 + int(wire["nsec"][0])
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=first_ns // 10**9, nanosec=first_ns % 10**9), frame_id=""
        )
        msg = T[PACKET_TYPES[1]](
            header=header,
            height=180,
            width=240,
            seq=index,
            time_base=first_ns + 10**12,
            encoding="mono",
            is_bigendian=False,
            events=encode_mono(first_ns, events),
        )
        return PACKET_TYPES[1], bytes(store.serialize_cdr(msg, PACKET_TYPES[1]))

    _rewrite(small_bags["sqlite3"], tmp_path / "bag", as_mono)
    assert Rosbag2Dataset(tmp_path / "bag").events().tobytes() == excerpt.events().tobytes()


@pytest.mark.parametrize("encoding", ["trigger", "my_codec"])
def test_packed_encodings_not_read_are_refused_by_name(small_bags, tmp_path, encoding):
    store = event_typestore()
    T = store.types

    def as_packet(topic, msgtype, index, raw):
        if topic != "/dvs/events":
            return msgtype, raw
        header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="")
        msg = T[PACKET_TYPES[0]](
            header=header,
            height=180,
            width=240,
            seq=index,
            time_base=0,
            encoding=encoding,
            is_bigendian=False,
            events=np.zeros(16, np.uint8),
        )
        return PACKET_TYPES[0], bytes(store.serialize_cdr(msg, PACKET_TYPES[0]))

    _rewrite(small_bags["mcap"], tmp_path / "bag", as_packet)
    for lenient in (False, True):
        with pytest.raises(
            DataError,
            match=rf"bag:/dvs/events:0: event encoding '{encoding}'.*\(eas-vo reads mono, evt3, libcaer, libcaer_cmp\)$",
        ):
            Rosbag2Dataset(tmp_path / "bag", BagConfig(lenient=lenient)).events()


def test_wrong_message_type_is_named(small_bags, tmp_path):
    def drop_images(topic, msgtype, index, raw):
        return None if topic == "/dvs/image_raw" else (msgtype, raw)

    _rewrite(small_bags["sqlite3"], tmp_path / "noframes", drop_images)
    ds = Rosbag2Dataset(tmp_path / "noframes")  # no image messages: an event-only stream
    assert ds.load_frame(0) is None and "an event-only stream" in ds.no_frames_reason
    with pytest.raises(DataError, match=r"topic /dvs/imu carries sensor_msgs/msg/Imu, expected sensor_msgs/msg/Image$"):
        Rosbag2Dataset(tmp_path / "noframes", BagConfig(image_topic="/dvs/imu"))
    with pytest.raises(
        DataError,
        match=r"topic /dvs/image_raw carries sensor_msgs/msg/Image, expected "
        r"dvs_msgs/msg/EventArray or event_camera_msgs/msg/EventPacket or",
    ):
        Rosbag2Dataset(small_bags["sqlite3"], BagConfig(events_topic="/dvs/image_raw")).events()


def test_empty_topics(excerpt, tmp_path):
    """Topics with a connection and no message: no frames, no events, no IMU, no ground truth."""
    from rosbags.rosbag2 import Writer

    from eas_vo.datasets.bags import recording_messages

    store = event_typestore()
    with Writer(tmp_path / "bag", version=9) as writer:
        connections = {}
        for t, topic, msgtype, msg in recording_messages(excerpt, BagConfig(), store, False, lambda events: iter(())):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            if msgtype == "sensor_msgs/msg/CameraInfo":
                writer.write(connections[topic], 0, store.serialize_cdr(msg, msgtype))
        writer.add_connection("/dvs/events", DVS_ARRAY, typestore=store)
    ds = Rosbag2Dataset(tmp_path / "bag")
    assert len(ds.events()) == 0 and ds.load_frame(0) is None and len(ds.frame_times()) == 0
    assert ds.imu is None and ds.ground_truth is None


def test_times_going_back(small_bags, excerpt, tmp_path):
    store = event_typestore()

    def restamp(target, index_back):
        def change(topic, msgtype, index, raw):
            if topic != target or index != index_back:
                return msgtype, raw
            msg = store.deserialize_cdr(raw, msgtype)
            msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0
            return msgtype, bytes(store.serialize_cdr(msg, msgtype))

        return change

    _rewrite(small_bags["mcap"], tmp_path / "frames", restamp("/dvs/image_raw", 2))
    with pytest.raises(DataError, match=r"frames:/dvs/image_raw:2: timestamp 0.000000000 goes back"):
        Rosbag2Dataset(tmp_path / "frames")
    lenient = Rosbag2Dataset(tmp_path / "frames", BagConfig(lenient=True))
    assert np.array_equal(lenient.frame_times(), excerpt.frame_times()[:2])
    assert "1 dropped: timestamp going back (first at message 2)" in lenient.data_warnings()[0]
    _rewrite(small_bags["mcap"], tmp_path / "imu", restamp("/dvs/imu", 5))
    with pytest.raises(DataError, match=r"imu:/dvs/imu:5: timestamp \S+ does not increase"):
        Rosbag2Dataset(tmp_path / "imu")


def test_definitions_come_from_the_bag(small_bags, tmp_path):
    """The bag's own definitions are registered (a type no typestore knows is read), and an
    event type the bag defines unlike its driver is refused by name."""
    from rosbags.rosbag2 import Reader, Writer
    from rosbags.typesys import get_types_from_msg

    store = event_typestore()
    store.register(get_types_from_msg("int32 answer", "my_msgs/msg/Thing"))
    foreign = "std_msgs/Header header\nuint32 height\nuint32 width\nuint8[] events"

    def copy(dst, events_definition):
        with Reader(small_bags["mcap"]) as reader, Writer(dst, version=9, storage_plugin=_mcap()) as writer:
            conns = {}
            for c in reader.connections:
                odd = c.topic == "/dvs/events" and events_definition is not None
                conns[c.id] = (
                    writer.add_connection(c.topic, c.msgtype, msgdef=events_definition, rihs01="RIHS01_" + "0" * 64)
                    if odd
                    else writer.add_connection(c.topic, c.msgtype, typestore=store)
                )
            thing = writer.add_connection("/thing", "my_msgs/msg/Thing", typestore=store)
            writer.write(
                thing, 1, store.serialize_cdr(store.types["my_msgs/msg/Thing"](answer=42), "my_msgs/msg/Thing")
            )
            for conn, t, raw in reader.messages():
                writer.write(conns[conn.id], t, raw)

    copy(tmp_path / "bag", None)
    with Reader(tmp_path / "bag") as reader:
        mine = bag_typestore(tmp_path / "bag", reader.connections)
        raw = next(raw for conn, _, raw in reader.messages() if conn.topic == "/thing")
    assert "my_msgs/msg/Thing" not in event_typestore().fielddefs
    assert mine.deserialize_cdr(raw, "my_msgs/msg/Thing").answer == 42
    assert len(Rosbag2Dataset(tmp_path / "bag").events()) > 0
    copy(tmp_path / "odd", foreign)
    with pytest.raises(
        DataError, match=r"odd: topic /dvs/events: the bag defines dvs_msgs/msg/EventArray unlike its driver$"
    ):
        Rosbag2Dataset(tmp_path / "odd")


def _mcap():
    from rosbags.rosbag2 import StoragePlugin

    return StoragePlugin.MCAP
