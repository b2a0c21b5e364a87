"""ROS 2 bags (rosbag2 folders, `.db3` sqlite3 and `.mcap` files), read with `rosbags`: no
ROS install needed.

The topics and the checks are the ROS 1 reader's (datasets/bags.py). Message definitions come
from the bag itself (rosbag2's sqlite3 `message_definitions` table, mcap schemas); for bags
written before rosbag2 stored them, from ROS 2 Humble's types and the event types below.

Events (configurable topic), in any of:
- `dvs_msgs/msg/EventArray` (the rpg DVS driver's ROS 2 port): decoded from its CDR bytes
  with numpy;
- `event_camera_msgs/msg/EventPacket` (ros-event-camera drivers: libcaer_driver,
  metavision_driver) and its former name `event_array_msgs/msg/EventArray`, in the encodings
  `mono`, `evt3`, `libcaer` and `libcaer_cmp` (datasets/bags.py PacketStream says on which clock).
"""

from __future__ import annotations

import re
import sqlite3
import struct
from pathlib import Path

import numpy as np

from eas_vo.datasets.bags import (
    EVENT_PACKET_FIELDS,
    PACKET_TYPES,
    BagConfig,
    BagDataset,
    RefusedEncoding,
    encode_mono,
    recording_messages,
    stamp_ns,
    write_messages,
)
from eas_vo.errors import DataError
from eas_vo.eventfile import file_identity
from eas_vo.plugins import Dataset

DVS_EVENT_MSG = """
uint16 x
uint16 y
builtin_interfaces/Time ts
bool polarity
"""
DVS_EVENT_ARRAY_MSG = """
std_msgs/Header header
uint32 height
uint32 width
dvs_msgs/Event[] events
"""
DVS_ARRAY = "dvs_msgs/msg/EventArray"
SQLITE_MAGIC = b"SQLite format 3\x00"
MCAP_MAGIC = b"\x89MCAP0\r\n"
#: What rosbags' rosbag2 readers raise on damaged bytes besides ReaderError: sqlite's errors,
#: short reads and failed asserts of the mcap parser, and the chunk decompressors' errors.
DAMAGED_BAG_ERRORS = (
    sqlite3.Error,
    AssertionError,
    KeyError,
    IndexError,
    ValueError,
    struct.error,
    OSError,
    EOFError,
    RuntimeError,
    UnicodeDecodeError,
)
#: dvs_msgs/msg/Event in CDR: the first element starts 4-aligned (x, y, sec, nsec, polarity:
#: 13 bytes + 1 of padding); every later one starts at 2 mod 4 and pads its time to 4: 16 bytes.
_FIRST_EVENT = np.dtype(
    {
        "names": ["x", "y", "sec", "nsec", "p"],
        "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
        "offsets": [0, 2, 4, 8, 12],
        "itemsize": 13,
    }
)
_LATER_EVENT = np.dtype(
    {
        "names": ["x", "y", "sec", "nsec", "p"],
        "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
        "offsets": [0, 2, 6, 10, 14],
        "itemsize": 15,
    }
)


def event_typestore():
    """A typestore of ROS 2 Humble's messages plus the event types above."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(DVS_EVENT_MSG, "dvs_msgs/msg/Event"))
    store.register(get_types_from_msg(DVS_EVENT_ARRAY_MSG, DVS_ARRAY))
    for msgtype in PACKET_TYPES:
        store.register(get_types_from_msg("std_msgs/Header header" + EVENT_PACKET_FIELDS, msgtype))
    return store


def bag_typestore(path: Path, connections):
    """The types of a bag's connections: its own definitions, then (for bags that store none)
    event_typestore()'s. A definition that cannot be parsed raises DataError naming the type."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    for conn in connections:
        fmt, text = conn.msgdef.format, conn.msgdef.data
        if fmt == MessageDefinitionFormat.NONE or conn.msgtype in store.fielddefs:
            continue
        try:
            if fmt == MessageDefinitionFormat.MSG:
                store.register(get_types_from_msg(text, conn.msgtype))
            else:
                separator = "=" * 80 + "\n"
                for block in text.split(separator)[1:] if text.startswith(separator + "IDL: ") else [text]:
                    idl = block.split("\n", 1)[1] if text.startswith(separator) else block
                    # `#include` lines are the C preprocessor's, not IDL: the types they name are blocks of their own
                    store.register(get_types_from_idl(re.sub(r"(?m)^[ \t]*#.*$", "", idl)))
        except (TypesysError, ValueError, IndexError) as exc:
            raise DataError(path, f"cannot read the bag's definition of {conn.msgtype} ({exc})") from None
    fallback = event_typestore()
    needed = {}

    def add(name):  # a type the bag does not define, and the types it nests
        if name in store.fielddefs or name in needed or name not in fallback.fielddefs:
            return
        needed[name] = fallback.fielddefs[name]
        for _, desc in fallback.fielddefs[name][1]:
            for nested in _nested_names(desc):
                add(nested)

    for conn in connections:
        add(conn.msgtype)
    if needed:
        store.register(needed)
    return store


def _nested_names(desc) -> list[str]:
    """The message type names a field description refers to."""
    from rosbags.interfaces import Nodetype

    kind, rest = desc
    if kind == Nodetype.NAME:
        return [rest]
    return _nested_names(rest[0]) if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) else []


def _definition(store, msgtype: str) -> list:
    """A type's fields with the nested types' fields spelled out (to compare definitions)."""
    from rosbags.interfaces import Nodetype

    def expand(desc):
        kind, rest = desc
        if kind == Nodetype.NAME:
            return _definition(store, rest)
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            return [kind, expand(rest[0]), rest[1]]
        return [kind, rest]

    return [(name.lower(), expand(desc)) for name, desc in store.fielddefs[msgtype][1]]


def decode_dvs_array(raw: bytes) -> np.ndarray:
    """CDR dvs_msgs/msg/EventArray -> records (x, y, sec, nsec, p) of its events."""
    if len(raw) < 4 or raw[:2] != b"\x00\x01":
        if raw[:2] == b"\x00\x00":
            raise RefusedEncoding("big-endian CDR is not read")
        raise ValueError("not a little-endian CDR message")
    body = memoryview(raw)[4:]
    frame_id_len = int(np.frombuffer(body, "<u4", 1, 8)[0]) if len(body) >= 12 else len(body)
    o = -(-(12 + frame_id_len) // 4) * 4
    if len(body) < o + 12:
        raise ValueError(f"{len(raw)} bytes end within the message's header")
    count = int(np.frombuffer(body, "<u4", 1, o + 8)[0])
    start = o + 12
    need = start + (16 * count - 3 if count else 0)
    if not need <= len(body) <= need + 3:  # (a writer may pad the message to a multiple of 4)
        raise ValueError(f"{count} events announced, {len(body) - start} bytes of event data")
    out = np.empty(count, _FIRST_EVENT)
    if count:
        out[:1] = np.frombuffer(body, _FIRST_EVENT, 1, start)
    if count > 1:
        later = np.ndarray((count - 1,), _LATER_EVENT, body, start + 14, (16,))
        for name in _LATER_EVENT.names:  # field by field: numpy copies a whole record of another layout slowly
            out[name][1:] = later[name]
    return out


def encode_dvs_array(t_header: float, width: int, height: int, events: np.ndarray, origin_ns: int = 0) -> bytes:
    """CDR dvs_msgs/msg/EventArray bytes (frame_id "davis"; times [s] after `origin_ns`), built
    with numpy; the inverse of decode_dvs_array, byte for byte what rosbags' serialize_cdr writes."""
    sec, nsec = divmod(origin_ns + int(round(t_header * 1e9)), 1_000_000_000)
    ns = np.round(events["t"] * 1e9).astype(np.int64) + origin_ns
    secs, nsecs = np.divmod(ns, 1_000_000_000)
    frame_id = b"davis\x00"
    head = struct.pack("<iiI", sec, nsec, len(frame_id)) + frame_id
    head += bytes(-len(head) % 4) + struct.pack("<III", height, width, len(events))
    body = bytearray(len(head) + (16 * len(events) - 3 if len(events) else 0))
    body[: len(head)] = head
    for part, dtype, offset in ((slice(0, 1), _FIRST_EVENT, 0), (slice(1, None), _LATER_EVENT, 14)):
        n = len(events[part])
        if n:
            rec = np.ndarray((n,), dtype, body, len(head) + offset, (16,))
            rec["x"], rec["y"], rec["sec"], rec["nsec"], rec["p"] = (
                events["x"][part],
                events["y"][part],
                secs[part],
                nsecs[part],
                events["p"][part] > 0,
            )
    return b"\x00\x01\x00\x00" + bytes(body)


class Rosbag2Dataset(BagDataset):
    """A ROS 2 bag (a rosbag2 folder, or one `.db3` / `.mcap` file of it) of an event camera."""

    name = "rosbag2"
    description = "ROS 2 bag (folder, .db3 or .mcap): dvs_msgs/event_camera_msgs events, sensor_msgs, mocap poses"
    cache_tag = "rosbag2"
    event_types = (DVS_ARRAY, *PACKET_TYPES)
    camera_fields = ("k", "d")

    def _open(self):
        from rosbags.rosbag2 import Reader, ReaderError

        path = self.path
        if not path.exists():
            raise DataError(path, "ROS 2 bag not found")
        if path.is_dir() and not (path / "metadata.yaml").is_file():
            raise DataError(path, "a folder without metadata.yaml is not a rosbag2 bag")
        if path.is_file() and _storage_of(path) is None:
            raise DataError(path, "not a ROS 2 bag file (neither sqlite3 nor mcap)")
        try:
            reader = Reader(_storage_file(path) if path.is_dir() else path)
            reader.open()
        except (ReaderError, *DAMAGED_BAG_ERRORS) as exc:
            raise DataError(path, f"not a readable ROS 2 bag ({_said(exc)})") from None
        self.store = bag_typestore(path, reader.connections)
        reference = event_typestore()
        for conn in reader.connections:
            if conn.msgtype in self.event_types and _definition(self.store, conn.msgtype) != _definition(
                reference, conn.msgtype
            ):
                raise DataError(path, f"topic {conn.topic}: the bag defines {conn.msgtype} unlike its driver")
        return reader

    def _damage_errors(self) -> tuple[type[BaseException], ...]:
        from rosbags.rosbag2 import ReaderError

        return (ReaderError, *DAMAGED_BAG_ERRORS)

    def _damage_detail(self, connections: list, index: int, exc: BaseException) -> str:
        return f" ({_said(exc)})"

    def _deserialize(self, raw: bytes, msgtype: str):
        return self.store.deserialize_cdr(raw, msgtype)

    def _decode_events(self, raw: bytes, msgtype: str, packets, index: int):
        if msgtype == DVS_ARRAY:
            wire = decode_dvs_array(raw)
            return stamp_ns(wire["sec"], wire["nsec"]), wire["x"], wire["y"], wire["p"]
        try:
            msg = self.store.deserialize_cdr(raw, msgtype)
        except Exception as exc:  # rosbags raises assorted errors on damaged data
            raise ValueError(str(exc) or type(exc).__name__) from None
        return packets.decode(msg, index)

    def _header_stamp_ns(self, raw: bytes) -> int:
        if raw[:2] != b"\x00\x01":
            raise RefusedEncoding("big-endian CDR is not read")
        sec, nsec = struct.unpack_from("<iI", raw, 4)  # after the CDR encapsulation: Header.stamp
        return sec * 1_000_000_000 + nsec

    def _identity(self) -> tuple:
        if self.path.is_file():
            return file_identity(self.path)
        files = [
            self.path / "metadata.yaml",
            *sorted(p for p in self.path.iterdir() if p.suffix in (".db3", ".mcap", ".zstd")),
        ]
        return tuple(part for f in files for part in (f.name, *file_identity(f)))

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A folder holding metadata.yaml, or a `.db3` / `.mcap` file that starts as one (its magic)."""
        path = Path(location)
        try:
            if path.is_dir():
                return (path / "metadata.yaml").is_file()
            return path.suffix.lower() in (".db3", ".mcap") and _storage_of(path) is not None
        except OSError:
            return False


def _storage_file(folder: Path) -> Path:
    """What to open of a rosbag2 folder: the folder, or where its metadata.yaml names no storage
    plugin (older rosbag2 wrote `storage_identifier: ""`, as rosbag2 itself then tells the
    storage by the files), its one bag file; DataError for what cannot be read so."""
    import yaml

    where = folder / "metadata.yaml"
    try:
        text = where.read_text(errors="replace")
        named = re.search(r"^\s*storage_identifier:\s*(\S*)", text, re.M)
        if named and named.group(1) not in ("", "''", '""'):
            return folder  # (the common case, without parsing the YAML twice)
        info = yaml.safe_load(text)["rosbag2_bagfile_information"]
        storage, files = info.get("storage_identifier"), list(info.get("relative_file_paths") or [])
    except (OSError, yaml.YAMLError, TypeError, KeyError, AttributeError):
        return folder  # (rosbags' reader says what is wrong with it)
    if storage or not isinstance(storage, str):
        return folder
    if len(files) != 1 or not isinstance(files[0], str) or _leaves(files[0]):
        raise DataError(
            where,
            f"names no storage plugin (storage_identifier is empty) and {len(files)} bag files: "
            "write the storage (sqlite3 or mcap) into it",
        )
    path = folder / files[0]
    if not path.is_file() or _storage_of(path) is None:
        raise DataError(
            where,
            f"names no storage plugin, and its file {files[0]} is "
            f"{'missing' if not path.is_file() else 'neither sqlite3 nor mcap'}",
        )
    return path


def _leaves(name: str) -> bool:
    """Whether a file named by metadata.yaml lies outside its folder."""
    return Path(name).is_absolute() or ".." in Path(name).parts


def _storage_of(path: Path) -> str | None:
    """`sqlite3` or `mcap` from a file's first bytes, or None."""
    with open(path, "rb") as fh:
        head = fh.read(len(SQLITE_MAGIC))
    if head == SQLITE_MAGIC:
        return "sqlite3"
    return "mcap" if head.startswith(MCAP_MAGIC) else None


def _said(exc: Exception) -> str:
    """What the reader said of damaged bytes, on one line (its failed asserts say nothing)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def write_bag2(
    dataset: Dataset,
    path: str | Path,
    storage: str = "sqlite3",
    config: BagConfig | None = None,
    encoding: str = "dvs",
    events_per_message: int = 5000,
) -> None:
    """Write a dataset as a rosbag2 folder `path` with rosbags' Writer (storage `sqlite3` or
    `mcap`); events as dvs_msgs/msg/EventArray (`encoding="dvs"`) or as `mono`
    event_camera_msgs/msg/EventPacket (`encoding="mono"`)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    c = config or BagConfig()
    store = event_typestore()
    cam = dataset.camera
    packet_type = PACKET_TYPES[0]
    origin_ns = dataset.clock_origin_ns

    def event_messages(events):
        for start in range(0, len(events), events_per_message):
            chunk = events[start : start + events_per_message]
            t = float(chunk["t"][-1])
            if encoding == "dvs":
                yield t, DVS_ARRAY, encode_dvs_array(t, cam.width, cam.height, chunk, origin_ns)
                continue
            time_base = origin_ns + int(round(float(chunk["t"][0]) * 1e9))
            sec, nsec = divmod(time_base, 1_000_000_000)
            header = store.types["std_msgs/msg/Header"](
                stamp=store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="davis"
            )
            msg = store.types[packet_type](
                header=header,
                height=cam.height,
                width=cam.width,
                seq=start // events_per_message,
                time_base=time_base,
                encoding="mono",
                is_bigendian=False,
                events=encode_mono(time_base, chunk, origin_ns),
            )
            yield t, packet_type, bytes(store.serialize_cdr(msg, packet_type))

    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    with Writer(Path(path), version=9, storage_plugin=plugin) as writer:
        write_messages(
            writer, recording_messages(dataset, c, store, False, event_messages), store, store.serialize_cdr, origin_ns
        )
