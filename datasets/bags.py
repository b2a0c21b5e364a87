"""What the ROS 1 (`rosbag`) and ROS 2 (`rosbag2`) readers share: their topics, the checks and
conversions of each message type, the cached event stream, and the messages their writers
build. Not a plugin.

A format reader subclasses BagDataset and says how to open its bag, iterate its raw messages,
deserialise one, and decode an event message into columns; everything else is here, so both
formats give the same recording the same arrays and the same errors.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, ClassVar, Iterator

import cv2
import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.datasets.calibration import camera_from_camera_info, check_frame_size
from eas_vo.datasets.recording import CALIBRATION_FORMATS, RecordingReader, StreamConfig, clock_origin_ns
from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, cache_key, load_cached, write_behind
from eas_vo.eventfile.packets import DECODERS, decoder_class
from eas_vo.io.tables import check_increasing
from eas_vo.io.tum import pose_series
from eas_vo.plugins import Dataset
from eas_vo.types import ImuSeries, empty_events

#: Event messages are decoded and checked in groups of about this many bytes (a worker thread
#: does it while the next group is read).
BLOCK_BYTES = 8 << 20


@dataclass(frozen=True)
class BagConfig(StreamConfig):
    """StreamConfig plus the topic names: where a default name is absent, the bag's one topic of
    that message type is read (the sensor size: CameraInfo's, else the images' or the event
    messages')."""

    events_topic: str = "/dvs/events"
    image_topic: str = "/dvs/image_raw"
    imu_topic: str = "/dvs/imu"
    pose_topic: str = "/optitrack/davis"
    camera_info_topic: str = "/dvs/camera_info"


class RefusedEncoding(Exception):
    """An event message this reader does not decode (not damage: never dropped under --lenient)."""


#: The fields of event_camera_msgs/msg/EventPacket (and of event_array_msgs/msg/EventArray
#: before its renaming) after its header, in either ROS version.
EVENT_PACKET_FIELDS = """
uint32 height
uint32 width
uint64 seq
uint64 time_base
string encoding
bool is_bigendian
uint8[] events
"""
PACKET_TYPES = ("event_camera_msgs/msg/EventPacket", "event_array_msgs/msg/EventArray")


def stamp_ns(sec, nsec) -> np.ndarray:
    """ROS time (sec, nanosec) -> int64 nanoseconds."""
    return np.asarray(sec, np.int64) * 1_000_000_000 + np.asarray(nsec, np.int64)


def decode_mono(base_ns: int, packed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """event_camera_codecs' `mono` encoding -> (t [ns], x, y, p) columns.

    Each event is one little-endian uint64: bits 0-31 its time dt [ns] after the packet's start,
    32-47 x, 48-62 y, 63 the polarity (1 = ON); t = base_ns + dt.
    """
    if len(packed) % 8:
        raise ValueError(f"{len(packed)} bytes of mono events, not a multiple of 8")
    words = np.frombuffer(np.ascontiguousarray(packed, np.uint8), "<u8")
    t_ns = np.int64(base_ns) + (words & 0xFFFFFFFF).astype(np.int64)
    return t_ns, (words >> 32) & 0xFFFF, (words >> 48) & 0x7FFF, words >> 63


def encode_mono(base_ns: int, events: np.ndarray, origin_ns: int = 0) -> np.ndarray:
    """Events (EVENT_DTYPE, t [s] after `origin_ns`, at or after base_ns, within 4.29 s of it) -> `mono` bytes."""
    dt = np.round(events["t"] * 1e9).astype(np.int64) + (origin_ns - base_ns)
    if len(dt) and not (0 <= dt.min() and dt.max() < 2**32):
        raise ValueError("mono packets span at most 4.29 s after their time base")
    words = (
        dt.astype(np.uint64)
        | events["x"].astype(np.uint64) << np.uint64(32)
        | events["y"].astype(np.uint64) << np.uint64(48)
        | (events["p"] > 0).astype(np.uint64) << np.uint64(63)
    )
    return words.astype("<u8").view(np.uint8)


class PacketStream:
    """The decoding state of one stream of EventPackets, read in order: a decoder per packed
    encoding (eventfile.packets), the offset from the sensor's clock to the bag's, and the
    external trigger edges met (reported, not events)."""

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        self.decoders = {}
        self.sensor_to_bag_ns: int | None = None
        self.triggers = 0
        self.first_trigger: int | None = None

    def decode(self, msg, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """EventPacket `index` of the stream -> (t [ns, the bag's clock], x, y, p); RefusedEncoding
        for what is not read.

        `mono`: the header stamp + each event's offset (ROS time, the clock of the bag's other
        topics). Encodings on the sensor's clock (Decoder.host_clock False, e.g. `evt3`): put on
        the bag's clock by one offset, the first packet's header stamp minus its first event's
        sensor time, so the sensor's own timing is kept exactly; those whose sensor clock was set
        to the host's at start (libcaer) are read as they are."""
        stamp = stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)
        if msg.is_bigendian:
            raise RefusedEncoding(f"big-endian {msg.encoding} events are not read")
        if msg.encoding == "mono":
            return decode_mono(int(stamp), msg.events)
        if msg.encoding not in self.decoders:
            cls = decoder_class(msg.encoding)
            if cls is None:
                what = (
                    "holds external trigger events only, not camera events"
                    if msg.encoding == "trigger"
                    else "is not read"
                )
                raise RefusedEncoding(
                    f"event encoding {msg.encoding!r} {what} (eas-vo reads mono, {', '.join(DECODERS)})"
                )
            self.decoders[msg.encoding] = cls(self.width, self.height)
        decoder = self.decoders[msg.encoding]
        out = decoder.decode(np.asarray(msg.events, np.uint8), int(msg.time_base))
        if len(out.trigger_t_ns) and self.first_trigger is None:
            self.first_trigger = index
        self.triggers += len(out.trigger_t_ns)
        if decoder.host_clock or not len(out.t_ns):
            return out.t_ns, out.x, out.y, out.p
        if self.sensor_to_bag_ns is None:
            self.sensor_to_bag_ns = int(stamp) - int(out.t_ns[0])
        return out.t_ns + self.sensor_to_bag_ns, out.x, out.y, out.p


def image_gray(where: str, index: int, msg) -> np.ndarray:
    """A sensor_msgs/Image (mono8, 8UC1, bgr8 or rgb8) -> grayscale uint8 (height, width)."""
    image = np.frombuffer(msg.data, np.uint8)
    channels = {"mono8": 1, "8UC1": 1, "bgr8": 3, "rgb8": 3}.get(msg.encoding)
    if channels is None or len(image) != msg.height * msg.step or msg.step < msg.width * channels:
        raise DataError(where, f"unsupported or inconsistent image ({msg.encoding}, {msg.width}x{msg.height})", index)
    image = image.reshape(msg.height, msg.step)[:, : msg.width * channels].reshape(msg.height, msg.width, channels)
    if channels == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY if msg.encoding == "rgb8" else cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(image[..., 0])


class BagDataset(RecordingReader):
    """A bag recorded by an event-camera driver: frames, events, IMU, motion capture, camera info.

    Subclasses set `cache_tag`, `event_types`, `camera_fields` and implement `_open`,
    `_damage_errors`, `_damage_detail`, `_deserialize`, `_decode_events` and `_identity`.
    """

    Config = BagConfig
    #: The format's part of the event cache key.
    cache_tag: ClassVar[str]
    #: The event message types the format decodes.
    event_types: ClassVar[tuple[str, ...]]
    #: CameraInfo's names of K and D in this ROS version.
    camera_fields: ClassVar[tuple[str, str]]

    def __init__(self, location: str | Path, config: BagConfig | None = None):
        self.config = config or BagConfig()
        self.path = Path(location)
        self.label = str(self.path)
        self.warnings = DataWarnings()
        self.reader = self._open()
        self.topic_types = {conn.topic: conn.msgtype for conn in self.reader.connections}
        self.topic = {key: self._find_topic(key, types) for key, types in self._topic_kinds().items()}
        self.clock_origin_ns = clock_origin_ns(self._first_stamp_ns())
        self._times, self._frames = self._read_images()
        if not self._frames:
            self.no_frames_reason = f"{self.path} has no image messages (an event-only stream)"
        self._sensor = self._sensor_size()
        given = self.calibration_file(*self._sensor)
        self.camera = given if given is not None else self._read_camera()
        if self.camera is not None:
            self._check_camera_size()
        self.ground_truth = self._read_poses() if not self.config.ground_truth else self.ground_truth_file()
        self.imu = self._read_imu()
        self._events = None

    def _topic_kinds(self) -> dict[str, tuple[str, ...]]:
        """Each topic option (a BagConfig field) and the message types it may carry."""
        return {
            "events_topic": self.event_types,
            "image_topic": ("sensor_msgs/msg/Image",),
            "imu_topic": ("sensor_msgs/msg/Imu",),
            "pose_topic": ("geometry_msgs/msg/PoseStamped",),
            "camera_info_topic": ("sensor_msgs/msg/CameraInfo",),
        }

    def _find_topic(self, key: str, types: tuple[str, ...]) -> str | None:
        """The topic `config.<key>` names; where its default name is absent, the one topic of the
        bag carrying one of `types` (a driver's own names), else None. A topic the user named
        that the bag lacks, or several candidates, raise DataError listing the bag's topics, those
        carrying `types` first."""
        named = getattr(self.config, key)
        if named in self.topic_types:
            return named
        found = sorted(topic for topic, msgtype in self.topic_types.items() if msgtype in types)
        if named != getattr(BagConfig, key):
            kind = (
                f"its {' or '.join(types)} topic{'s' if len(found) > 1 else ''}: {', '.join(found)} "
                f"(--set dataset.{key}={found[0]}); "
                if found
                else f"it has no {' or '.join(types)} topic; "
            )
            raise DataError(self.path, f"has no topic {named} (dataset.{key}); {kind}it holds {self._topic_list()}")
        if len(found) > 1:
            raise DataError(
                self.path,
                f"has no {named} and {len(found)} topics of its kind ({', '.join(found)}): "
                f"choose one with --set dataset.{key}=TOPIC",
            )
        return found[0] if found else None

    def _first_stamp_ns(self) -> int:
        """The header stamp [ns] of the first message of the events, else images, IMU or poses
        (read from its bytes: every one of these types starts with its header)."""
        for key in ("events_topic", "image_topic", "imu_topic", "pose_topic"):
            for index, _, raw in self._messages(self.topic[key], self._topic_kinds()[key], deserialize=False):
                if len(raw) < 12:
                    raise DataError(f"{self.path}:{self.topic[key]}", "message too short for its header", index)
                try:
                    return self._header_stamp_ns(raw)
                except RefusedEncoding as exc:
                    raise DataError(f"{self.path}:{self.topic[key]}", str(exc), index) from None
        return 0

    def _header_stamp_ns(self, raw: bytes) -> int:
        """A serialised message's header stamp [ns] (its first field)."""
        raise NotImplementedError

    def _seconds(self, t_ns) -> np.ndarray:
        """Times [ns] of the bag's clock -> float64 seconds after its clock_origin_ns."""
        return (np.asarray(t_ns, np.int64) - self.clock_origin_ns) / 1e9

    def _stamp_s(self, msg) -> float:
        """A message's header stamp [s after the clock origin]."""
        return float(self._seconds(stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)))

    def _topic_list(self) -> str:
        return ", ".join(f"{topic} ({msgtype})" for topic, msgtype in sorted(self.topic_types.items())) or "no topics"

    def contents(self) -> list[str]:
        counts = {}
        for conn in self.reader.connections:
            counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
        lines = [f"topic {topic}: {self.topic_types[topic]}, {n} messages" for topic, n in sorted(counts.items())]
        encoding = self._event_encoding()
        if encoding:
            lines.append(f"event encoding {encoding}")
        return lines

    # -- what a format provides ----------------------------------------------------------

    def _open(self):
        """The opened rosbags reader; DataError when the bag is missing or unreadable."""
        raise NotImplementedError

    def _records(self, topic: str, connections: list) -> Iterator[tuple[object, bytes]]:
        """(connection, raw bytes) of each message of `connections`, in time order; damaged bag
        bytes raise DataError naming the topic, the message's index in it and `_damage_detail`."""
        records = self.reader.messages(connections=connections)
        index = 0
        while True:
            try:
                conn, _, raw = next(records)
            except StopIteration:
                return
            except self._damage_errors() as exc:
                raise DataError(
                    f"{self.path}:{topic}",
                    "damaged bag data, message unreadable" + self._damage_detail(connections, index, exc),
                    index,
                ) from None
            yield conn, raw
            index += 1

    def _damage_errors(self) -> tuple[type[BaseException], ...]:
        """What the format's reader raises on damaged bytes."""
        raise NotImplementedError

    def _damage_detail(self, connections: list, index: int, exc: BaseException) -> str:
        """What follows "message unreadable" for message `index` of `connections` (e.g. " (what the reader said)")."""
        raise NotImplementedError

    def _deserialize(self, raw: bytes, msgtype: str):
        raise NotImplementedError

    def _decode_events(
        self, raw: bytes, msgtype: str, packets: PacketStream, index: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Event message `index` -> (t [ns, the bag's clock], x, y, p) columns (an EventPacket
        through `packets.decode`); ValueError for damaged bytes, RefusedEncoding for what the
        reader does not decode."""
        raise NotImplementedError

    def _identity(self) -> tuple:
        """What identifies the bag's content for the event cache (file_identity of its files)."""
        raise NotImplementedError

    @functools.cached_property
    def _first_event_message(self):
        """(msgtype, message) of the first event message, deserialised once, or None."""
        for _, msgtype, msg in self._messages(self.topic["events_topic"], self.event_types):
            return msgtype, msg
        return None

    def _event_encoding(self) -> str:
        """The packed encoding of the first event message (`mono`, `evt3`), or '' for an event array."""
        first = self._first_event_message
        return first[1].encoding if first is not None and first[0] in PACKET_TYPES else ""

    def _event_message_size(self) -> tuple[int, int] | None:
        """(width, height) [px] the first event message states, or None (no events, or zero)."""
        first = self._first_event_message
        return (
            (int(first[1].width), int(first[1].height))
            if first is not None and first[1].width and first[1].height
            else None
        )

    # -- shared reading ------------------------------------------------------------------

    def _messages(self, topic: str | None, msgtypes: tuple[str, ...], deserialize: bool = True):
        """(index, msgtype, message or raw bytes) of a topic (none for None); a wrong type, or a
        message that fails to decode, names the topic and the index."""
        connections = [conn for conn in self.reader.connections if conn.topic == topic]
        if not connections:
            return  # (an empty selection would mean every topic to rosbags)
        for conn in connections:
            if conn.msgtype not in msgtypes:
                raise DataError(self.path, f"topic {topic} carries {conn.msgtype}, expected {' or '.join(msgtypes)}")
        for index, (conn, raw) in enumerate(self._records(topic, connections)):
            if not deserialize:
                yield index, conn.msgtype, raw
                continue
            try:
                yield index, conn.msgtype, self._deserialize(raw, conn.msgtype)
            except Exception as exc:  # rosbags raises assorted errors on damaged data
                raise DataError(f"{self.path}:{topic}", f"cannot decode message ({exc})", index) from None

    def _read_images(self):
        times, frames = [], []
        where = f"{self.path}:{self.topic['image_topic']}"
        for index, _, msg in self._messages(self.topic["image_topic"], ("sensor_msgs/msg/Image",)):
            image = image_gray(where, index, msg)
            t = self._stamp_s(msg)
            if times and t < times[-1]:
                if not self.config.lenient:
                    raise DataError(where, f"timestamp {t:.9f} goes back (previous {times[-1]:.9f})", index)
                self.warnings.add(where, "timestamp going back", f"message {index}")
                continue
            times.append(t)
            frames.append(image)
        return (np.array(times) if frames else None), frames

    @functools.cached_property
    def _camera_info(self):
        """(where, message) of the first CameraInfo message, if any."""
        topic = self.topic["camera_info_topic"]
        for index, _, msg in self._messages(topic, ("sensor_msgs/msg/CameraInfo",)):
            return f"{self.path}:{topic}:{index}", msg
        return None

    def _sensor_size(self) -> tuple[int, int]:
        """(width, height) [px]: the frames', else what the event messages state, else CameraInfo's
        (the data's own size first: _check_camera_size holds the calibration to it)."""
        if self._frames:
            return self._frames[0].shape[1], self._frames[0].shape[0]
        size = self._event_message_size()
        if size is not None:
            return size
        info = self._camera_info
        if info is None:
            raise DataError(
                self.path,
                "the sensor size is unknown: no CameraInfo, no images, and the event messages "
                "state none; give a calibration with --set dataset.calibration=FILE",
            )
        return int(info[1].width), int(info[1].height)

    def _check_camera_size(self) -> None:
        """A DataError unless the camera (CameraInfo's or dataset.calibration's) is for the size of
        the frames and of the sensor the event messages state."""
        if self._frames:
            height, width = self._frames[0].shape
            check_frame_size(self.camera, width, height, f"{self.path}:{self.topic['image_topic']}:0", "its frames are")
        size = self._event_message_size()
        if size is not None:
            check_frame_size(
                self.camera,
                *size,
                f"{self.path}:{self.topic['events_topic']}:0",
                "its event messages state a sensor of",
            )

    def _read_camera(self) -> CameraModel | None:
        info = self._camera_info
        if info is None:
            self.no_camera_reason = (
                f"{self.path} holds no CameraInfo message: give the intrinsics with --set "
                f"dataset.calibration=FILE ({CALIBRATION_FORMATS})"
            )
            return None
        where, msg = info
        K_name, D_name = self.camera_fields
        return camera_from_camera_info(
            where,
            int(msg.width),
            int(msg.height),
            getattr(msg, K_name),
            getattr(msg, D_name),
            msg.distortion_model,
            f"{K_name}/{D_name}",
        )

    def _read_poses(self):
        topic = self.topic["pose_topic"]
        rows = [
            (
                self._stamp_s(m),
                m.pose.position.x,
                m.pose.position.y,
                m.pose.position.z,
                m.pose.orientation.x,
                m.pose.orientation.y,
                m.pose.orientation.z,
                m.pose.orientation.w,
            )
            for _, _, m in self._messages(topic, ("geometry_msgs/msg/PoseStamped",))
        ]
        if not rows:
            return None
        table = np.array(rows)
        keep = check_increasing(f"{self.path}:{topic}", table[:, 0], _message_index, self.tolerated, "message")
        return pose_series(f"{self.path}:{topic}", table[keep], lambda row: _message_index(int(keep[row])))

    def _read_imu(self):
        topic = self.topic["imu_topic"]
        rows = [
            (
                self._stamp_s(m),
                m.linear_acceleration.x,
                m.linear_acceleration.y,
                m.linear_acceleration.z,
                m.angular_velocity.x,
                m.angular_velocity.y,
                m.angular_velocity.z,
            )
            for _, _, m in self._messages(topic, ("sensor_msgs/msg/Imu",))
        ]
        if not rows:
            return None
        table = np.array(rows)
        table = table[check_increasing(f"{self.path}:{topic}", table[:, 0], _message_index, self.tolerated, "message")]
        return ImuSeries(table[:, 0], table[:, 1:4], table[:, 4:7])

    # -- plugin contract -----------------------------------------------------------------

    def load_frame(self, k: int):
        return self._frames[k] if self._frames else None

    def events(self) -> np.ndarray:
        if self._events is None:
            self._events = self._load_events()
        return self._events

    def _load_events(self) -> np.ndarray:
        c = self.config
        topic = self.topic["events_topic"]
        if topic is None:
            return empty_events()
        width, height = self._sensor
        where = f"{self.path}:{topic}"

        def fill(out, warnings):
            validate = Validator(where, width, height, c.time_tolerance_s, c.lenient, warnings, "message")
            packets = PacketStream(width, height)

            def checked(messages) -> list[np.ndarray]:
                """The valid events of (index, msgtype, raw) messages, decoded, in order."""
                kept = []
                for index, msgtype, raw in messages:
                    try:
                        t_ns, x, y, p = self._decode_events(raw, msgtype, packets, index)
                    except RefusedEncoding as exc:
                        raise DataError(where, str(exc), index) from None
                    except (ValueError, IndexError) as exc:
                        if not c.lenient:
                            raise DataError(where, f"cannot decode event message ({exc})", index) from None
                        warnings.add(where, "undecodable event message", f"message {index}")
                        continue
                    kept.append(validate(self._seconds(t_ns), x, y, p, lambda row: index))
                return kept  # (not joined: numpy copies the packed records slowly)

            def blocks():  # messages grouped by about BLOCK_BYTES, decoded and checked behind the reading
                group, size = [], 0
                for message in self._messages(topic, self.event_types, deserialize=False):
                    group.append(message)
                    size += len(message[2])
                    if size >= BLOCK_BYTES:
                        yield functools.partial(checked, group)
                        group, size = [], 0
                if group:
                    yield functools.partial(checked, group)

            written = write_behind(out, blocks())
            if packets.triggers:
                warnings.add(
                    where,
                    "external trigger edges, not camera events (kept apart)",
                    f"message {packets.first_trigger}",
                    packets.triggers,
                )
            for decoder in packets.decoders.values():
                for n, what in (
                    (decoder.outside, "events outside the sensor"),
                    (decoder.skipped, "events before the stream's first full timestamp"),
                ):
                    if n:
                        warnings.add(where, f"{what} ({decoder.encoding})", "the decoder's count", n)
            return written

        key = cache_key(
            self.cache_tag, *self._identity(), topic, width, height, c.time_tolerance_s, self.clock_origin_ns
        )
        return load_cached(key, c.lenient, self.warnings, fill, where)


def _message_index(row: int) -> int:
    """Rows of a topic's table are named by their message index (from 0, as rosbags counts)."""
    return row


# -- writing: the messages of a recording, for either ROS version ----------------------------


def write_messages(writer, messages, store, serialize, origin_ns: int = 0) -> None:
    """Write `messages` ((t [s after origin_ns], topic, msgtype, message or its bytes), as
    recording_messages yields them) with a rosbags writer, one connection per topic;
    `serialize(msg, msgtype)` turns a message into bytes (ROS 1 or CDR)."""
    connections = {}
    for t, topic, msgtype, msg in messages:
        if topic not in connections:
            connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
        writer.write(
            connections[topic], bag_time_ns(t, origin_ns), msg if isinstance(msg, bytes) else serialize(msg, msgtype)
        )


def recording_messages(
    dataset: Dataset,
    config: BagConfig,
    store,
    ros1: bool,
    event_messages: Callable[[np.ndarray], Iterator[tuple[float, str, object]]],
):
    """(t [s], topic, msgtype, message or bytes) of a dataset's camera info, frames, events, IMU
    and ground truth, built with rosbags' `store` types (ROS 1 or ROS 2 field names), in time
    order. `event_messages(events)` yields the event messages (t, msgtype, bytes)."""
    c = config
    T = store.types
    cam = dataset.camera

    origin_ns = dataset.clock_origin_ns

    def header(t: float):
        sec, nsec = divmod(origin_ns + int(round(t * 1e9)), 1_000_000_000)
        stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        return T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), stamp=stamp, frame_id="davis")

    def vec(x, y, z):
        return T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    messages = []
    t0 = float(dataset.frame_times()[0]) if len(dataset.frame_times()) else 0.0
    K = np.asarray(cam.K, float)
    matrices = {
        "D": np.asarray(cam.dist, float),
        "K": K.ravel(),
        "R": np.eye(3).ravel(),
        "P": np.column_stack([K, np.zeros(3)]).ravel(),
    }
    info = T["sensor_msgs/msg/CameraInfo"](
        header=header(t0),
        height=cam.height,
        width=cam.width,
        distortion_model="equidistant" if cam.model == "equidistant" else "plumb_bob",
        **{(name if ros1 else name.lower()): value for name, value in matrices.items()},
        binning_x=0,
        binning_y=0,
        roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )
    messages.append((t0, c.camera_info_topic, "sensor_msgs/msg/CameraInfo", info))
    for k, t in enumerate(dataset.frame_times()):
        frame = dataset.load_frame(k)
        if frame is None:
            break
        msg = T["sensor_msgs/msg/Image"](
            header=header(t),
            height=frame.shape[0],
            width=frame.shape[1],
            encoding="mono8",
            is_bigendian=0,
            step=frame.shape[1],
            data=np.ascontiguousarray(frame).ravel(),
        )
        messages.append((t, c.image_topic, "sensor_msgs/msg/Image", msg))
    messages.extend((t, c.events_topic, msgtype, raw) for t, msgtype, raw in event_messages(dataset.events()))
    if dataset.imu is not None:
        zero_cov = np.zeros(9)
        for t, acc, gyro in zip(dataset.imu.t, dataset.imu.acc, dataset.imu.gyro):
            msg = T["sensor_msgs/msg/Imu"](
                header=header(t),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=zero_cov,
                angular_velocity=vec(*gyro),
                angular_velocity_covariance=zero_cov,
                linear_acceleration=vec(*acc),
                linear_acceleration_covariance=zero_cov,
            )
            messages.append((t, c.imu_topic, "sensor_msgs/msg/Imu", msg))
    gt = dataset.ground_truth
    if gt is not None:
        for t, p, q in zip(gt.t, gt.p_w_c, gt.q_w_c):
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])),
                orientation=T["geometry_msgs/msg/Quaternion"](
                    x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
                ),
            )
            messages.append(
                (
                    t,
                    c.pose_topic,
                    "geometry_msgs/msg/PoseStamped",
                    T["geometry_msgs/msg/PoseStamped"](header=header(t), pose=pose),
                )
            )
    return sorted(messages, key=lambda m: m[0])


def bag_time_ns(t: float, origin_ns: int = 0) -> int:
    """A message's bag time [ns] for a stamp t [s after origin_ns] (bags hold no negative times)."""
    return max(origin_ns + int(round(t * 1e9)), 0)
