"""AEDAT4 files (iniVation's DV) read without dv-processing: the stream description, the
packets of every stream, event packets, frames and IMU readings, each bounded by its bytes.

An AEDAT4 file is the magic line, an int32 length and an `IOHeader` FlatBuffer (compression,
the byte where the packet index starts, an XML description of the streams: type, name, sensor
size), then packets, each an 8-byte header (int32 stream id, int32 body size) and a body
compressed as a whole (LZ4 or Zstandard frame, or not at all) that holds a size-prefixed
FlatBuffer:
- `EVTS` (events): a table whose field 0 is a vector of 16-byte `Event` structs (int64
  timestamp [us], int16 x, int16 y, bool polarity, 3 bytes of padding);
- `FRME` (one frame): a table of int64 timestamps [us] (0: the frame's, the start of its
  exposure; 3, 4: start and end of exposure), int8 format (5: an OpenCV type code), int16
  width, height, position x, y (6-9), the pixels (10: a uint8 vector, rows of
  width x channels), int64 exposure [us] (11);
- `IMUS` (IMU readings): a table whose field 0 is a vector of `IMU` tables: int64 timestamp
  [us] (0), float32 accelerometer x, y, z [g] (2-4) and gyroscope x, y, z [deg/s] (5-7).
(The field numbers as dv-processing 2.0's MonoCameraWriter writes them.)

dv-processing reads the same files through an unchecked FlatBuffer access and its own LZ4
loop: given one flipped bit it spun for minutes holding the GIL (so Ctrl-C and SIGTERM were
never seen), or crashed; it is not given the file. Here every offset is bounds-checked, the
file's packets are found by walking their headers (the index at the end is not needed), and
damage is a one-line DataError naming the stream and the packet.

`Aedat4File` finds the packets once (8 bytes read per packet) and decodes any of them
independently. cramjam's LZ4 and Zstandard decoders release the GIL (python-lz4's frame
decoder does not), so event packets decompress on worker threads
(eas_vo.concurrency.in_order), each into a reused buffer (`Scratch`), sparing a fresh
buffer's page faults (docs/speed.md, "Recordings in other formats", has what each choice
costs or saves; benchmarks/bench_events.py --only aedat4 times the reader).
"""

from __future__ import annotations

import mmap
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from eas_vo.errors import DataError

#: The first bytes of every AEDAT 4.0 file.
MAGIC = b"#!AER-DAT4.0\r\n"
#: DV's `Event` struct as stored in an event packet.
PACKET_EVENT = np.dtype(
    {"names": ["t", "x", "y", "p"], "formats": ["<i8", "<i2", "<i2", "u1"], "offsets": [0, 8, 10, 12], "itemsize": 16}
)
#: IOHeader's compression enum -> the codec of the packet bodies.
CODECS = {0: "none", 1: "lz4", 2: "lz4", 3: "zstd", 4: "zstd"}


class _FlatBuffer:
    """Bounds-checked reads of little-endian scalars in a FlatBuffer; `fail(what)` raises."""

    def __init__(self, data, fail):
        self.data, self.fail = data, fail

    def scalar(self, fmt: str, at: int):
        if at < 0 or at + struct.calcsize(fmt) > len(self.data):
            self.fail(f"an offset points outside the buffer (byte {at} of {len(self.data)})")
        return struct.unpack_from(fmt, self.data, at)[0]

    def field(self, table: int, index: int) -> int:
        """Absolute position of field `index` of the table at `table`, or 0 if absent."""
        vtable = table - self.scalar("<i", table)
        vtable_bytes = self.scalar("<H", vtable)
        slot = 4 + 2 * index
        offset = self.scalar("<H", vtable + slot) if slot + 2 <= vtable_bytes else 0
        return table + offset if offset else 0

    def value(self, fmt: str, table: int, index: int, default=0):
        """Scalar field `index` of the table at `table` (`default` when absent, as FlatBuffers
        leaves out a field equal to its default)."""
        at = self.field(table, index)
        return self.scalar(fmt, at) if at else default

    def follow(self, at: int) -> int:
        """The position an unsigned offset stored at `at` points to."""
        return at + self.scalar("<I", at)

    def vector(self, table: int, index: int, item_bytes: int) -> tuple[int, int]:
        """(position of the first element, count) of vector field `index` ((0, 0) when absent);
        its elements must lie inside the buffer."""
        at = self.field(table, index)
        if not at:
            return 0, 0
        vector = self.follow(at)
        count = self.scalar("<I", vector)
        if vector + 4 + item_bytes * count > len(self.data):
            self.fail(f"its vector of {count} elements runs past its end")
        return vector + 4, count

    def root(self, identifier: bytes) -> int:
        """The root table of a size-prefixed FlatBuffer with file identifier `identifier`."""
        claimed = self.scalar("<I", 0)
        if claimed > len(self.data) - 4:
            self.fail(f"its FlatBuffer claims {claimed} bytes, {len(self.data) - 4} are there")
        tag = bytes(self.data[8:12])
        if tag != identifier:
            self.fail(f"it holds {tag!r}, not {identifier.decode()!r}")
        return self.follow(4)


_OK, _SHORT, _NOT_EVENTS, _OUTSIDE, _PAST_END = range(5)
_PROBLEMS = {
    _SHORT: "its FlatBuffer claims {a} bytes, {b} are there",
    _NOT_EVENTS: "it holds {tag!r}, not events ('EVTS')",
    _OUTSIDE: "an offset points outside the buffer (byte {a} of {b})",
    _PAST_END: "its {a} events run past its end",
}


@numba.njit(cache=True, nogil=True, inline="always")
def _uint(data, at, size):
    """The little-endian unsigned integer of `size` bytes at `at` (the caller checked the bounds)."""
    value = 0
    for i in range(size):
        value |= np.int64(data[at + i]) << (8 * i)
    return value


@numba.njit(cache=True, nogil=True)
def _event_vector(data):
    """Where an event packet's events are in its decompressed bytes `data` (uint8): (_OK,
    byte offset, count), count 0 for a packet without its events field; else (problem, a, b)
    with the values _PROBLEMS names. The size-prefixed FlatBuffer: uint32 size, uint32 root
    offset, the identifier `EVTS`, the root table's vtable, its field 0 (an offset to the
    vector: uint32 count, then 16-byte events); every offset is checked against the end."""
    n = len(data)
    if n < 4:
        return _OUTSIDE, 0, n
    if _uint(data, 0, 4) > n - 4:
        return _SHORT, _uint(data, 0, 4), n - 4
    if n < 12 or not (data[8] == 69 and data[9] == 86 and data[10] == 84 and data[11] == 83):  # "EVTS"
        return _NOT_EVENTS, 0, 0
    root = 4 + _uint(data, 4, 4)
    if root + 4 > n:
        return _OUTSIDE, root, n
    back = _uint(data, root, 4)
    vtable = root - (back - (1 << 32) if back >= 1 << 31 else back)  # a signed offset
    if vtable < 0 or vtable + 2 > n:
        return _OUTSIDE, vtable, n
    if _uint(data, vtable, 2) < 6:  # the vtable ends before field 0: no events
        return _OK, 0, 0
    if vtable + 6 > n:
        return _OUTSIDE, vtable + 4, n
    field = _uint(data, vtable + 4, 2)
    if field == 0:  # field 0 absent
        return _OK, 0, 0
    elements = root + field
    if elements + 4 > n:
        return _OUTSIDE, elements, n
    vector = elements + _uint(data, elements, 4)
    if vector + 4 > n:
        return _OUTSIDE, vector, n
    count = _uint(data, vector, 4)
    if vector + 4 + 16 * count > n:
        return _PAST_END, count, 0
    return _OK, vector + 4, count


class Scratch:
    """A decompression buffer reused packet after packet; it grows to twice a packet that did
    not fit."""

    def __init__(self, size: int = 1 << 20):
        self.buffer = np.empty(size, np.uint8)


#: The streams eas-vo reads: DV's type identifier -> the name DV's camera modules give the
#: stream (the one chosen when a file has several of that type).
STREAMS = {"events": b"EVTS", "frames": b"FRME", "imu": b"IMUS"}
#: A frame's format (an OpenCV type code) -> its channels: 8-bit grey, BGR, BGRA.
FRAME_CHANNELS = {0: 1, 16: 3, 24: 4}
#: One IMU reading as read: timestamp [us], accelerometer x, y, z [g], gyro x, y, z [deg/s].
IMU_FIELDS = (("<q", 0), ("<f", 2), ("<f", 3), ("<f", 4), ("<f", 5), ("<f", 6), ("<f", 7))


@dataclass(frozen=True)
class Stream:
    """One stream of the file: its id, the sensor size its description gives ((width, height)
    [px], None without one) and its packets' (body offset, body size) in file order."""

    id: int
    size: tuple[int, int] | None
    packets: list[tuple[int, int]] = field(default_factory=list)


@dataclass(frozen=True)
class DvFrame:
    """A frame as DV stores it: start of exposure and exposure [us], position [px], the
    pixels (height x width, x channels when not grey; a view of the decompressed packet)."""

    start_us: int
    exposure_us: int
    position: tuple[int, int]
    image: np.ndarray


class Aedat4File:
    """The streams eas-vo reads from the AEDAT4 file at `path`: `streams` maps "events",
    "frames", "imu" to a Stream (absent: the file has none); `event_records(k)`, `frame(k)`,
    `imu_rows()` decode their packets.

    Raises DataError (one line, naming the file and what is wrong) for a header, stream
    description or packet walk that does not hold together, and (naming the stream and the
    packet) for a packet that does not decode.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        with open(self.path, "rb") as fh:
            empty = fh.seek(0, 2) == 0  # mmap refuses an empty file
            self._map = b"" if empty else mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        self._data = memoryview(self._map)
        size = len(self._map)
        if self._map[: len(MAGIC)] != MAGIC or size < len(MAGIC) + 4:
            self._fail("not an AEDAT4 file")
        header_bytes = struct.unpack_from("<i", self._map, len(MAGIC))[0]
        start = len(MAGIC) + 4
        if not 0 < header_bytes <= size - start:
            self._fail(f"its header claims {header_bytes} bytes, {size - start} follow")
        codec, table_at, description = self._read_header(self._data[start : start + header_bytes])
        self.codec = codec
        self.streams = {kind: self._stream(description, kind) for kind in STREAMS}
        self.streams = {kind: stream for kind, stream in self.streams.items() if stream is not None}
        end = size if table_at < 0 else table_at
        if end > size:
            self._fail(f"truncated: its packet index should start at byte {table_at}, the file has {size} bytes")
        self._walk(start + header_bytes, end)

    def __len__(self) -> int:
        """The number of event packets."""
        return len(self.streams["events"].packets) if "events" in self.streams else 0

    @property
    def sizes(self) -> list[int]:
        """Each event packet's stored (compressed) size [bytes]."""
        return [size for _, size in self.streams["events"].packets] if "events" in self.streams else []

    def _fail(self, what: str, stream: str = ""):
        raise DataError(f"{self.path}:{stream}" if stream else self.path, what)

    def _read_header(self, header) -> tuple[str, int, ET.Element]:
        fb = _FlatBuffer(header, lambda what: self._fail(f"damaged AEDAT4 header: {what}"))
        root = fb.follow(0)
        compression = fb.value("<i", root, 0)
        codec = CODECS.get(compression)
        if codec is None:
            self._fail(f"unknown compression {compression} in its header")
        table_at = fb.value("<q", root, 1, -1)
        info = fb.field(root, 2)
        if not info:
            self._fail("damaged AEDAT4 header: no stream description")
        text_at = fb.follow(info)
        length = fb.scalar("<I", text_at)
        if text_at + 4 + length > len(header):
            self._fail("damaged AEDAT4 header: its stream description runs past the header")
        try:
            description = ET.fromstring(bytes(header[text_at + 4 : text_at + 4 + length]).decode("utf-8"))
        except (ET.ParseError, UnicodeDecodeError) as exc:
            self._fail(f"damaged AEDAT4 header: its stream description is not XML ({exc})")
        return codec, table_at, description

    def _stream(self, description: ET.Element, kind: str) -> Stream | None:
        """The one stream of type STREAMS[kind] (if several, the one named `kind`); None if none."""
        found = {}
        for node in description.iter("node"):
            attrs = {a.get("key"): a.text for a in node.findall("attr")}
            if attrs.get("typeIdentifier") == STREAMS[kind].decode() and node.get("name", "").isdigit():
                found[int(node.get("name"))] = (attrs.get("originalOutputName") or "", node)
        named = [k for k, (name, _) in found.items() if name == kind]
        if len(found) > 1 and len(named) != 1:
            names = ", ".join(sorted(name for name, _ in found.values()))
            self._fail(f"{len(found)} {kind} streams ({names}): eas-vo reads one camera's")
        if not found:
            return None
        stream_id = (named or list(found))[0]
        return Stream(stream_id, self._sensor_size(found[stream_id][1], stream_id))

    def _sensor_size(self, node: ET.Element, stream_id: int) -> tuple[int, int] | None:
        """(sizeX, sizeY) [px] of a stream's `info` node, None without them."""
        info = node.find("node[@name='info']")
        attrs = {a.get("key"): (a.text or "").strip() for a in (info.findall("attr") if info is not None else ())}
        if "sizeX" not in attrs and "sizeY" not in attrs:
            return None
        try:
            size = int(attrs.get("sizeX", "")), int(attrs.get("sizeY", ""))
        except ValueError:
            size = (0, 0)
        if not all(0 < n <= 1 << 15 for n in size):  # DV's sizes are int16
            self._fail(
                f"damaged AEDAT4 header: stream {stream_id}'s sensor size is "
                f"{attrs.get('sizeX')!r} x {attrs.get('sizeY')!r}, not two positive integers"
            )
        return size

    def _walk(self, at: int, end: int) -> None:
        """Note the (body offset, body size) of each packet between byte `at` and `end` in its stream."""
        by_id = {stream.id: stream.packets for stream in self.streams.values()}
        index = 0
        while at < end:
            if at + 8 > end:
                self._fail(f"truncated: packet {index} at byte {at} has no whole header")
            stream, size = struct.unpack_from("<ii", self._map, at)
            if size < 0 or at + 8 + size > end:
                self._fail(
                    f"truncated or damaged: packet {index} at byte {at} claims {size} bytes, {end - at - 8} follow"
                )
            if stream in by_id:
                by_id[stream].append((at + 8, size))
            at, index = at + 8 + size, index + 1

    def _body(self, kind: str, k: int, scratch: Scratch | None):
        """Packet k of stream `kind`, decompressed (into `scratch` if given), and its `fail`."""
        offset, size = self.streams[kind].packets[k]
        what = {"events": "event", "frames": "frame", "imu": "IMU"}[kind]

        def fail(problem):
            self._fail(f"damaged AEDAT4 {what} packet {k} (at byte {offset - 8}): {problem}", kind)

        body = self._data[offset : offset + size]
        return (self._decompress(body, scratch, fail) if self.codec != "none" else body), fail

    def event_records(self, k: int, scratch: Scratch | None = None) -> np.ndarray:
        """Event packet k's events as PACKET_EVENT records: a view of its decompressed bytes, in
        `scratch` if given (valid until its next use)."""
        body, fail = self._body("events", k, scratch)
        data = np.frombuffer(body, np.uint8)
        status, a, b = _event_vector(data)
        if status != _OK:
            fail(_PROBLEMS[status].format(a=a, b=b, tag=bytes(data[8:12])))
        return np.frombuffer(body, PACKET_EVENT, b, a)

    def frame(self, k: int) -> DvFrame:
        """Frame packet k (DV writes one frame a packet)."""
        body, fail = self._body("frames", k, None)
        fb = _FlatBuffer(body, fail)
        root = fb.root(STREAMS["frames"])
        start_us = fb.value("<q", root, 0)
        exposure_us = fb.value("<q", root, 11, None)
        if exposure_us is None:  # written before the field existed: the exposure's end - start
            exposure_us = fb.value("<q", root, 4) - fb.value("<q", root, 3)
        kind = fb.value("<b", root, 5)
        width, height = fb.value("<h", root, 6), fb.value("<h", root, 7)
        channels = FRAME_CHANNELS.get(kind)
        if channels is None:
            fail(f"frame format {kind}: 8-bit grey, BGR or BGRA are read")
        first, count = fb.vector(root, 10, 1)
        if width <= 0 or height <= 0 or count != width * height * channels:
            fail(f"{count} bytes of pixels for a {width}x{height} frame of {channels} channel(s)")
        image = np.frombuffer(body, np.uint8, count, first).reshape(
            (height, width, channels)[: 2 if channels == 1 else 3]
        )
        return DvFrame(start_us, exposure_us, (fb.value("<h", root, 8), fb.value("<h", root, 9)), image)

    def imu_rows(self) -> np.ndarray:
        """Every IMU reading, in file order: rows of IMU_FIELDS (float64)."""
        rows = []
        for k in range(len(self.streams["imu"].packets)):
            body, fail = self._body("imu", k, None)
            fb = _FlatBuffer(body, fail)
            first, count = fb.vector(fb.root(STREAMS["imu"]), 0, 4)
            for i in range(count):
                reading = fb.follow(first + 4 * i)
                rows.append([fb.value(fmt, reading, index) for fmt, index in IMU_FIELDS])
        return np.array(rows, dtype=float).reshape(-1, len(IMU_FIELDS))

    def _decompress(self, body, scratch: Scratch | None, fail) -> memoryview:
        """The packet body decompressed, into `scratch` when it fits (else into memory of its
        own, and the scratch grown for the next packet); `fail` on damage."""
        import cramjam

        codec = getattr(cramjam, self.codec)
        if scratch is not None:
            try:
                return memoryview(scratch.buffer)[: codec.decompress_into(body, scratch.buffer)]
            except cramjam.DecompressionError:
                pass  # too large for the buffer, or damaged: decompressing it on its own tells which
        try:
            data = memoryview(codec.decompress(body))
        except cramjam.DecompressionError as exc:
            fail(f"{self.codec} cannot decompress it ({exc})")
        if scratch is not None:
            scratch.buffer = np.empty(2 * len(data), np.uint8)
        return data
