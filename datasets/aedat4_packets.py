"""The event packets of an AEDAT4 file, decoded without dv-processing.

dv-processing decodes under the GIL, one packet after the other, so a first read through it
could not use a second core. An AEDAT4 file is simple enough to read directly: the magic
line, an int32 length and an `IOHeader` FlatBuffer (compression, the byte where the packet
index starts, an XML description of the streams), then packets, each an 8-byte header (int32
stream id, int32 body size) and a body compressed as a whole (LZ4 or Zstandard frame, or not
at all) that holds a size-prefixed FlatBuffer. An event packet's FlatBuffer (identifier
`EVTS`) is a table whose first field is a vector of 16-byte `Event` structs (int64 timestamp
[us], int16 x, int16 y, bool polarity, 3 bytes of padding).

`EventPackets` finds the event stream's packets once (8 bytes read per packet) and decodes any
of them independently. cramjam's LZ4 and Zstandard decoders release the GIL (python-lz4's frame
decoder does not: two threads took as long as one), so packets decompress on worker threads
(eas_vo.concurrency.in_order), each into a reused buffer (`Scratch`): a fresh buffer per packet
cost more in page faults, and in the address-space lock both threads' faults queue on, than the
decompression itself.
Every offset is bounds-checked; damage is a one-line DataError naming the packet.
"""

from __future__ import annotations

import mmap
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import numba
import numpy as np

from eas_vo.errors import DataError

#: The first bytes of every AEDAT 4.0 file.
MAGIC = b"#!AER-DAT4.0\r\n"
#: DV's `Event` struct as stored in an event packet.
PACKET_EVENT = np.dtype({"names": ["t", "x", "y", "p"], "formats": ["<i8", "<i2", "<i2", "u1"],
                         "offsets": [0, 8, 10, 12], "itemsize": 16})
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
        return table + self.scalar("<H", vtable + slot) if slot + 2 <= vtable_bytes else 0

    def follow(self, at: int) -> int:
        """The position an unsigned offset stored at `at` points to."""
        return at + self.scalar("<I", at)


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


class EventPackets:
    """The event stream's packets of the AEDAT4 file at `path`: `len()` of them, `decode(k)`.

    Raises DataError (one line, naming the file and what is wrong) for a header, stream
    description or packet walk that does not hold together.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        with open(self.path, "rb") as fh:
            self._map = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        self._data = memoryview(self._map)
        size = len(self._map)
        if self._map[: len(MAGIC)] != MAGIC or size < len(MAGIC) + 4:
            self._fail("not an AEDAT4 file")
        header_bytes = struct.unpack_from("<i", self._map, len(MAGIC))[0]
        start = len(MAGIC) + 4
        if not 0 < header_bytes <= size - start:
            self._fail(f"its header claims {header_bytes} bytes, {size - start} follow")
        codec, table_at, streams = self._read_header(self._data[start : start + header_bytes])
        self.codec = codec
        self.stream_id = self._event_stream(streams)
        end = size if table_at < 0 else table_at
        if end > size:
            self._fail(f"truncated: its packet index should start at byte {table_at}, the file has {size} bytes")
        self._packets = self._walk(start + header_bytes, end)

    def __len__(self) -> int:
        return len(self._packets)

    @property
    def sizes(self) -> list[int]:
        """Each event packet's stored (compressed) size [bytes]."""
        return [size for _, size in self._packets]

    def _fail(self, what: str, stream: str = ""):
        raise DataError(f"{self.path}:{stream}" if stream else self.path, what)

    def _read_header(self, header) -> tuple[str, int, ET.Element]:
        fb = _FlatBuffer(header, lambda what: self._fail(f"damaged AEDAT4 header: {what}"))
        root = fb.follow(0)
        compression = fb.field(root, 0)
        codec = CODECS.get(fb.scalar("<i", compression) if compression else 0)
        if codec is None:
            self._fail(f"unknown compression {fb.scalar('<i', compression)} in its header")
        table = fb.field(root, 1)
        table_at = fb.scalar("<q", table) if table else -1
        info = fb.field(root, 2)
        if not info:
            self._fail("damaged AEDAT4 header: no stream description")
        text_at = fb.follow(info)
        length = fb.scalar("<I", text_at)
        if text_at + 4 + length > len(header):
            self._fail("damaged AEDAT4 header: its stream description runs past the header")
        try:
            streams = ET.fromstring(bytes(header[text_at + 4 : text_at + 4 + length]).decode("utf-8"))
        except (ET.ParseError, UnicodeDecodeError) as exc:
            self._fail(f"damaged AEDAT4 header: its stream description is not XML ({exc})")
        return codec, table_at, streams

    def _event_stream(self, streams: ET.Element) -> int | None:
        """The id of the one event stream (`EVTS`; if several, the one named `events`); None if none."""
        found = {}
        for node in streams.iter("node"):
            attrs = {a.get("key"): a.text for a in node.findall("attr")}
            if attrs.get("typeIdentifier") == "EVTS" and node.get("name", "").isdigit():
                found[int(node.get("name"))] = attrs.get("originalOutputName", "")
        named = [k for k, name in found.items() if name == "events"]
        if len(found) > 1 and len(named) != 1:
            self._fail(f"{len(found)} event streams ({', '.join(map(str, sorted(found.values())))}): eas-vo reads one camera's")
        return (named or list(found) or [None])[0]

    def _walk(self, at: int, end: int) -> list[tuple[int, int]]:
        """(body offset, body size) of each event packet between byte `at` and `end`."""
        packets, index = [], 0
        while at < end:
            if at + 8 > end:
                self._fail(f"truncated: packet {index} at byte {at} has no whole header")
            stream, size = struct.unpack_from("<ii", self._map, at)
            if size < 0 or at + 8 + size > end:
                self._fail(f"truncated or damaged: packet {index} at byte {at} claims {size} bytes, {end - at - 8} follow")
            if stream == self.stream_id:
                packets.append((at + 8, size))
            at, index = at + 8 + size, index + 1
        return packets

    def decode(self, k: int, scratch: Scratch | None = None) -> np.ndarray:
        """Packet k's events as PACKET_EVENT records: a view of its decompressed bytes, in
        `scratch` if given (valid until its next use)."""
        offset, size = self._packets[k]
        body = self._data[offset : offset + size]

        def fail(what):
            self._fail(f"damaged AEDAT4 event packet {k} (at byte {offset - 8}): {what}", "events")

        if self.codec != "none":
            body = self._decompress(body, scratch, fail)
        data = np.frombuffer(body, np.uint8)
        status, a, b = _event_vector(data)
        if status != _OK:
            fail(_PROBLEMS[status].format(a=a, b=b, tag=bytes(data[8:12])))
        return np.frombuffer(body, PACKET_EVENT, b, a)

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
