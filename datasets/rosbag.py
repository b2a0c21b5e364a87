"""ROS1 bags of the Event Camera Dataset, read with `rosbags` (no ROS install needed).

Topics (configurable): `/dvs/events` (dvs_msgs/EventArray), `/dvs/image_raw`
(sensor_msgs/Image), `/dvs/imu` (sensor_msgs/Imu), `/optitrack/davis`
(geometry_msgs/PoseStamped), `/dvs/camera_info` (sensor_msgs/CameraInfo).
Event arrays are decoded straight from their serialised bytes with numpy; the rest of the
reading is shared with the ROS 2 reader (datasets/bags.py).
"""

from __future__ import annotations

import struct
from functools import cache
from pathlib import Path

import numpy as np

from eas_vo.datasets.bags import (
    EVENT_PACKET_FIELDS,
    PACKET_TYPES,
    BagConfig,
    BagDataset,
    recording_messages,
    stamp_ns,
    write_messages,
)
from eas_vo.errors import DataError
from eas_vo.eventfile import file_identity
from eas_vo.plugins import Dataset

EVENT_MSG = """
uint16 x
uint16 y
time ts
bool polarity
"""
EVENT_ARRAY_MSG = """
Header header
uint32 height
uint32 width
dvs_msgs/Event[] events
"""
#: The sensor_msgs/CameraInfo distortion_model a lens model is written as.
ROS_DISTORTION_NAMES = {"radtan": "plumb_bob", "equidistant": "equidistant"}
#: What rosbags' reader raises on damaged bytes besides its ReaderError: failed asserts, unknown
#: connection ids, undecodable header text, short reads of its own parsing, and what the chunk
#: decompressors raise (bz2: OSError, EOFError, ValueError; lz4: RuntimeError).
DAMAGED_BAG_ERRORS = (AssertionError, KeyError, IndexError, ValueError, struct.error, OSError, EOFError, RuntimeError)
#: Serialised dvs_msgs/Event: x, y, ts.sec, ts.nsec, polarity (13 bytes, packed).
_EVENT_WIRE = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])


def _said(exc: Exception) -> str:
    """What the reader said of damaged bytes; nothing for its failed asserts and lookups."""
    return "" if isinstance(exc, (AssertionError, KeyError)) else str(exc)


@cache
def typestore():
    """ROS1 Noetic message types plus dvs_msgs."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(EVENT_MSG, "dvs_msgs/msg/Event"))
    store.register(get_types_from_msg(EVENT_ARRAY_MSG, "dvs_msgs/msg/EventArray"))
    for msgtype in PACKET_TYPES:
        store.register(get_types_from_msg("Header header" + EVENT_PACKET_FIELDS, msgtype))
    return store


def decode_event_array(raw: bytes) -> np.ndarray:
    """Serialised dvs_msgs/EventArray -> wire records (x, y, sec, nsec, p)."""
    frame_id_len = int(np.frombuffer(raw, "<u4", 1, 12)[0])
    offset = 16 + frame_id_len + 8
    count = int(np.frombuffer(raw, "<u4", 1, offset)[0])
    if len(raw) != offset + 4 + count * _EVENT_WIRE.itemsize:
        raise ValueError(f"{count} events announced, {len(raw) - offset - 4} bytes of event data")
    return np.frombuffer(raw, _EVENT_WIRE, count, offset + 4)


class RosbagDataset(BagDataset):
    """A ROS1 `.bag` recorded by the DAVIS driver (frames, events, IMU, motion capture)."""

    name = "rosbag"
    description = "ROS1 .bag (dvs_msgs events, sensor_msgs images/IMU/camera_info, mocap poses)"
    cache_tag = "bag"
    event_types = ("dvs_msgs/msg/EventArray", *PACKET_TYPES)
    camera_fields = ("K", "D")

    def _open(self):
        from rosbags.rosbag1 import Reader, ReaderError

        if not self.path.is_file():
            raise DataError(self.path, "bag file not found")
        try:
            reader = Reader(self.path)
            reader.open()
        except (ReaderError, *DAMAGED_BAG_ERRORS) as exc:
            raise DataError(self.path, f"not a readable ROS1 bag ({_said(exc) or 'a damaged index'})") from None
        return reader

    def _deserialize(self, raw: bytes, msgtype: str):
        return typestore().deserialize_ros1(raw, msgtype)

    def _decode_events(self, raw: bytes, msgtype: str, packets, index: int):
        if msgtype in PACKET_TYPES:
            try:
                msg = typestore().deserialize_ros1(raw, msgtype)
            except Exception as exc:  # rosbags raises assorted errors on damaged data
                raise ValueError(str(exc) or type(exc).__name__) from None
            return packets.decode(msg, index)
        wire = decode_event_array(raw)
        return stamp_ns(wire["sec"], wire["nsec"]), wire["x"], wire["y"], wire["p"]

    def _identity(self) -> tuple:
        return file_identity(self.path)

    def _header_stamp_ns(self, raw: bytes) -> int:
        seq, sec, nsec = struct.unpack_from("<III", raw)  # ROS 1 Header: seq, then time
        return sec * 1_000_000_000 + nsec

    def _damage_errors(self) -> tuple[type[BaseException], ...]:
        from rosbags.rosbag1 import ReaderError

        return (ReaderError, *DAMAGED_BAG_ERRORS)

    def _damage_detail(self, connections: list, index: int, exc: BaseException) -> str:
        """The message's bag time, and what the reader said."""
        t_ns = sorted(entry.time for c in connections for entry in self.reader.indexes[c.id])[index]
        return f" at bag time {t_ns / 1e9:.6f} s" + (f" ({_said(exc)})" if _said(exc) else "")

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A path ending in `.bag`."""
        return Path(location).suffix.lower() == ".bag"


def _serialise_event_array(t_header: float, width: int, height: int, events: np.ndarray, origin_ns: int = 0) -> bytes:
    """dvs_msgs/EventArray bytes (times [s] after `origin_ns`), built with numpy (millions of events stay fast)."""
    sec, nsec = divmod(origin_ns + int(round(t_header * 1e9)), 1_000_000_000)
    wire = np.empty(len(events), _EVENT_WIRE)
    ns = np.round(events["t"] * 1e9).astype(np.int64) + origin_ns
    wire["sec"], wire["nsec"] = np.divmod(ns, 1_000_000_000)
    wire["x"], wire["y"], wire["p"] = events["x"], events["y"], events["p"] > 0
    head = np.array([0, sec, nsec, 0, height, width, len(events)], "<u4").tobytes()
    return head + wire.tobytes()


def write_bag(
    dataset: Dataset, path: str | Path, config: BagConfig | None = None, events_per_message: int = 5000
) -> None:
    """Write a dataset (frames, events, IMU, ground truth, camera info) as a ROS1 bag."""
    from rosbags.rosbag1 import Writer

    c = config or BagConfig()
    store = typestore()
    cam = dataset.camera

    def event_messages(events):
        for start in range(0, len(events), events_per_message):
            chunk = events[start : start + events_per_message]
            t = float(chunk["t"][-1])
            yield (
                t,
                "dvs_msgs/msg/EventArray",
                _serialise_event_array(t, cam.width, cam.height, chunk, dataset.clock_origin_ns),
            )

    Path(path).unlink(missing_ok=True)
    with Writer(Path(path)) as writer:
        write_messages(
            writer,
            recording_messages(dataset, c, store, True, event_messages),
            store,
            store.serialize_ros1,
            dataset.clock_origin_ns,
        )
