"""Prophesee's own recordings (Metavision, OpenEB): `.raw` files of EVT 2.0, 2.1 or 3.0 words and
`.dat` files of CD event records. Events only (no frames, no IMU, no calibration); the external
trigger edges a `.raw` holds are counted in `contents` and returned by `triggers()`.

`.raw`: ASCII header lines `% key value` (OpenEB's generic header: up to a `% end` line, or the
first line not starting with `% `), then the words (eas_vo.eventfile.prophesee decodes them).
The format is the header's `% format NAME;width=W;height=H[;endianness=legacy]` (EVT3, EVT2,
EVT21), else its older `% evt 3.0|2.0|2.1` line; the sensor size the format's width and height,
else a `% geometry WxH` line, else dataset.width and dataset.height.

`.dat`: header lines `% key value` (`% Width W`, `% Height H`), one byte of event type (0:
Event2D, 12: EventCD) and one of record size (8), then records of a little-endian uint32 time
[us] and a uint32 with x (bits 0-13), y (bits 14-27) and polarity (bits 28-31) (OpenEB's
metavision_core/event_io/dat_tools.py). Its 32-bit time rolls over every 71.6 minutes: a time
going back by more than half of that is read as a roll-over.

Time: the file's microsecond clock (from the camera's start, near 0) -> float64 seconds.
"""

from __future__ import annotations

import functools
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.datasets.calibration import MAX_SENSOR_PX
from eas_vo.datasets.recording import CALIBRATION_FORMATS, RecordingReader, StreamConfig
from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, cache_key, cache_path, file_identity, load_cached, write_behind
from eas_vo.eventfile.prophesee import DECODERS, Evt21Decoder, PropheseeDecoder, WordError
from eas_vo.io.atomic import atomic_file
from eas_vo.validation import check_range

#: The most header bytes read (a header longer than this is not a Prophesee one).
HEADER_LIMIT = 1 << 20
#: Bytes of words (or records) decoded at a time: memory bounded by it.
BLOCK_BYTES = 4 << 20
#: A `.raw` header's older `% evt` values, as format names.
EVT_VERSIONS = {"3.0": "EVT3", "2.0": "EVT2", "2.1": "EVT21"}
#: `.dat` event types of CD events (OpenEB's Event2D and EventCD), with their record size [bytes].
DAT_CD_TYPES = {0: "Event2D", 12: "EventCD"}
DAT_OTHER_TYPES = {14: "EventExtTrigger", 40: "EventOpticalFlow"}
DAT_RECORD_BYTES = 8


@dataclass(frozen=True)
class PropheseeConfig(StreamConfig):
    """StreamConfig plus the sensor size of a file whose header states none.

    Attributes:
        width, height: sensor size [px]; 0: the header's (an error where it states none). A
            header that states one must agree.
    """

    width: int = 0
    height: int = 0

    def validate(self) -> None:
        super().validate()
        check_range(self, "width", 0, MAX_SENSOR_PX)
        check_range(self, "height", 0, MAX_SENSOR_PX)


@dataclass(frozen=True)
class Header:
    """A Prophesee file's header: its `% key value` lines (the first of each key) and where the
    data begin [bytes]."""

    fields: dict[str, str]
    data_offset: int


def read_header(path: Path) -> Header:
    """The `% key value` lines at the start of `path`, up to a `% end` line (consumed) or the
    first line that does not start with `% ` (OpenEB's rule)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(HEADER_LIMIT)
    except OSError as exc:
        raise DataError(path, f"cannot read: {exc.strerror or exc}") from None
    fields: dict[str, str] = {}
    pos = 0
    while head.startswith(b"% ", pos):
        end = head.find(b"\n", pos)
        if end < 0:
            raise DataError(path, f"header line at byte {pos} does not end within the first {HEADER_LIMIT} bytes")
        key, _, value = head[pos + 2 : end].decode("latin-1").strip().partition(" ")
        pos = end + 1
        if key == "end":
            break
        if key:
            fields.setdefault(key, value.strip())
    return Header(fields, pos)


def has_header(path: Path) -> bool:
    """Whether `path` is a file starting with a `% ` header line (never raises)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(2) == b"% "
    except (OSError, ValueError):
        return False


class PropheseeDataset(RecordingReader):
    """A Prophesee `.raw` (EVT 2.0, 2.1, 3.0) or `.dat` recording: events, and a `.raw`'s triggers."""

    name = "prophesee"
    description = "Prophesee .raw (EVT 2.0, 2.1, 3.0) or .dat recording: events only; --set dataset.calibration=FILE"
    Config = PropheseeConfig

    def __init__(self, location: str | Path, config: PropheseeConfig | None = None):
        self.config = config or PropheseeConfig()
        self.path = Path(location)
        self.label = str(self.path)
        self.warnings = DataWarnings()
        if not self.path.is_file():
            raise DataError(self.path, "Prophesee file not found")
        self.kind = self.path.suffix.lower()
        if self.kind not in (".raw", ".dat"):
            raise DataError(self.path, "a Prophesee recording is a .raw or a .dat file")
        self.header = read_header(self.path)
        if not self.header.fields:
            raise DataError(self.path, "has no `% key value` header lines: not a Prophesee file")
        self.size = self.path.stat().st_size
        if self.kind == ".raw":
            self.format, self.legacy = self._raw_format()
            width, height, self._size_source = self._sensor(*self._raw_geometry())
        else:
            self.format, self.legacy = self._dat_format(), False
            width, height, self._size_source = self._sensor(
                self._dat_side("Width"), self._dat_side("Height"), "the header's Width and Height"
            )
        self._size_px = (width, height)
        self.camera = self.calibration_file(width, height)
        if self.camera is None:
            self.no_camera_reason = (
                f"{self.path} holds no lens calibration: give one with --set dataset.calibration=FILE "
                f"({CALIBRATION_FORMATS})"
            )
        self.no_frames_reason = f"{self.path} holds events only (a Prophesee recording has no frames)"
        self.ground_truth = self.ground_truth_file()
        self._times = None
        self._events: np.ndarray | None = None
        self._summary: dict[str, np.ndarray] | None = None

    # -- the header ----------------------------------------------------------------------

    def _raw_format(self) -> tuple[str, bool]:
        """(format name, EVT 2.1 legacy word order) of a `.raw` header."""
        fields = self.header.fields
        if "format" in fields:
            name = fields["format"].split(";")[0].strip().upper()
        elif "evt" in fields:
            name = EVT_VERSIONS.get(fields["evt"], f"evt {fields['evt']}")
        else:
            raise DataError(
                self.path, "the header names no event format (a `% format EVT3;width=W;height=H` or `% evt 3.0` line)"
            )
        if name not in DECODERS:
            raise DataError(self.path, f"event format {name} is not read (EVT 2.0, 2.1 and 3.0 are)")
        endianness = self._format_options().get("endianness", fields.get("endianness", ""))
        return name, name == "EVT21" and endianness == "legacy"

    def _format_options(self) -> dict[str, str]:
        parts = self.header.fields.get("format", "").split(";")[1:]
        return dict(part.strip().partition("=")[::2] for part in parts if part.strip())

    def _raw_geometry(self) -> tuple[int | None, int | None, str]:
        """(width, height, where the header states them) of a `.raw`, None where it states none."""
        options, fields = self._format_options(), self.header.fields
        size = [self._count(options.get(key), f"format's {key}") for key in ("width", "height")]
        if "geometry" in fields:
            w, _, h = fields["geometry"].partition("x")
            geometry = [self._count(w, "geometry"), self._count(h, "geometry")]
            if None in geometry:
                raise DataError(self.path, f"header line `% geometry {fields['geometry']}` is not WIDTHxHEIGHT")
            if None not in size and size != geometry:
                raise DataError(
                    self.path,
                    f"the header's format says {size[0]}x{size[1]} px, its geometry {geometry[0]}x{geometry[1]}",
                )
            return geometry[0], geometry[1], "the header's geometry"
        return size[0], size[1], "the header's format"

    def _dat_format(self) -> str:
        """The `.dat` record type after the header (CD events only)."""
        with open(self.path, "rb") as fh:
            fh.seek(self.header.data_offset)
            kind = fh.read(2)
        if len(kind) < 2:
            raise DataError(self.path, f"ends at byte {self.size} inside its header: no event type and size bytes")
        ev_type, ev_size = kind
        if ev_type not in DAT_CD_TYPES:
            what = DAT_OTHER_TYPES.get(ev_type, f"event type {ev_type}")
            raise DataError(self.path, f"holds {what} records: only CD events (types 0 and 12) are read")
        if ev_size != DAT_RECORD_BYTES:
            raise DataError(
                self.path, f"{DAT_CD_TYPES[ev_type]} records of {ev_size} bytes (they are {DAT_RECORD_BYTES})"
            )
        return DAT_CD_TYPES[ev_type]

    def _dat_side(self, key: str) -> int | None:
        return self._count(self.header.fields.get(key), key)

    def _count(self, text: str | None, key: str) -> int | None:
        """A header's size in px (None if absent); not a positive integer is an error naming its key."""
        if text is None or text == "":
            return None
        if not text.strip().isdigit() or not 0 < int(text) <= MAX_SENSOR_PX:
            raise DataError(self.path, f"header's {key} {text!r} is not a sensor size (1 to {MAX_SENSOR_PX} px)")
        return int(text)

    def _sensor(self, width: int | None, height: int | None, source: str) -> tuple[int, int, str]:
        """(width, height, where they come from) of the sensor: the header's, else the config's;
        both given must agree."""
        c = self.config
        if width is None or height is None:
            if not (c.width and c.height):
                raise DataError(
                    self.path,
                    "the header states no sensor size: give it with --set dataset.width=W --set dataset.height=H",
                )
            return c.width, c.height, "dataset.width, dataset.height"
        if (c.width or c.height) and (c.width, c.height) != (width, height):
            raise DataError(
                self.path, f"dataset.width, dataset.height say {c.width}x{c.height} px, {source} {width}x{height}"
            )
        return width, height, source

    # -- events ----------------------------------------------------------------------------

    @property
    def sensor_size(self) -> tuple[int, int]:
        return self._size_px

    def load_frame(self, k: int) -> None:
        return None

    def events(self) -> np.ndarray:
        if self._events is None:
            self._events = self._load_events()
        return self._events

    def triggers(self) -> np.ndarray:
        """The external trigger edges of a `.raw`: t [s] (the events' clock), edge (1 rising,
        0 falling) and channel, in the file's order (none for a `.dat`)."""
        s = self._trigger_summary()
        out = np.empty(len(s["t_us"]), [("t", "<f8"), ("edge", "u1"), ("id", "u1")])
        out["t"], out["edge"], out["id"] = s["t_us"] / 1e6, s["edge"], s["id"]
        return out

    def _key(self) -> str:
        width, height = self._size_px
        return cache_key(
            "prophesee",
            *file_identity(self.path),
            self.format,
            self.legacy,
            width,
            height,
            self.config.time_tolerance_s,
        )

    def _blocks(self, block_bytes: int = BLOCK_BYTES):
        """(byte offset in the file, uint8 array) of the data after the header, in blocks of whole words."""
        start = self.header.data_offset + (2 if self.kind == ".dat" else 0)
        with open(self.path, "rb") as fh:
            fh.seek(start)
            offset = start
            while True:
                data = np.frombuffer(fh.read(block_bytes), np.uint8)
                if not len(data):
                    return
                yield offset, data
                offset += len(data)

    def _decoder(self) -> PropheseeDecoder:
        width, height = self._size_px
        return (
            Evt21Decoder(width, height, self.legacy) if self.format == "EVT21" else DECODERS[self.format](width, height)
        )

    def _decoded(self, triggers: list):
        """The Decoded of a `.raw`'s blocks in order, the decoder's state carried; each block's
        triggers appended to `triggers` and, at the end, the decoder's counts (outside, skipped).
        Damage raises DataError naming the byte."""
        decoder = self._decoder()
        for offset, data in self._blocks():
            try:
                decoded = decoder.decode(data)
            except WordError as exc:
                raise DataError(
                    self.path, f"byte {offset + exc.offset}: damaged {decoder.title} data: {exc.reason}"
                ) from None
            triggers.append((decoded.trigger_t_ns // 1000, decoded.trigger_edge, decoded.trigger_id))
            yield decoded
        triggers.append((decoder.outside, decoder.skipped))

    def _load_events(self) -> np.ndarray:
        c = self.config
        width, height = self._size_px
        where = str(self.path)
        key = self._key()
        triggers: list = []

        def fill(out, warnings):
            validate = Validator(where, width, height, c.time_tolerance_s, c.lenient, warnings, "event")

            def blocks():
                before = 0
                if self.kind == ".raw":
                    columns = ((d.t_ns, d.x, d.y, d.p, 1e9) for d in self._decoded(triggers))
                else:
                    columns = ((*records, 1e6) for records in self._dat_blocks())
                for t, x, y, p, per_second in columns:
                    yield functools.partial(validate, t, x, y, p, lambda row, first=before: first + row, per_second)
                    before += len(t)

            return write_behind(out, blocks())

        events = load_cached(
            key,
            c.lenient,
            self.warnings,
            fill,
            where,
            (self.size - self.header.data_offset) // DAT_RECORD_BYTES if self.kind == ".dat" else 0,
        )
        if self.kind == ".raw":
            if triggers:  # decoded now (not read from the cache)
                self._summary = self._save_summary(key, triggers)
            outside = self._trigger_summary()["counts"][0]
            if outside:
                self.warnings.add(
                    where,
                    f"event outside the {width}x{height} sensor (Prophesee's decoders drop them too)",
                    "decoding",
                    int(outside),
                )
        return events

    def _dat_blocks(self):
        """(t [us], x, y, p) of a `.dat`'s records, in blocks; a cut record is an error. The 32-bit
        time rolls over every 2^32 us: a time going back by more than half of that is a roll-over
        (+2^32 us, as expelliarmus reads it); a smaller step back stays one (the Validator's)."""
        carry, last = 0, None
        for offset, data in self._blocks(BLOCK_BYTES - BLOCK_BYTES % DAT_RECORD_BYTES):
            whole = len(data) - len(data) % DAT_RECORD_BYTES
            if whole != len(data):
                raise DataError(
                    self.path,
                    f"byte {offset + whole}: the file ends inside an event record "
                    f"({len(data) - whole} of its {DAT_RECORD_BYTES} bytes)",
                )
            words = data.view("<u4").reshape(-1, 2)
            t32, d = words[:, 0].astype(np.int64), words[:, 1]
            loops = carry + np.cumsum(np.diff(t32, prepend=t32[0] if last is None else last) < -(1 << 31))
            carry, last = int(loops[-1]), int(t32[-1])
            yield t32 + (loops << 32), d & 0x3FFF, (d >> 14) & 0x3FFF, d >> 28

    # -- triggers and decoder counts: a small cache beside the events' ---------------------------

    def _summary_path(self, key: str) -> Path:
        return cache_path(key).with_suffix(".triggers.npz")

    def _save_summary(self, key: str, triggers: list) -> dict[str, np.ndarray]:
        """Cache what _decoded put in `triggers`: (t [us], edge, id) per block, then the counts."""
        *blocks, counts = triggers
        t_us, edge, channel = (
            (np.concatenate(column) for column in zip(*blocks))
            if blocks
            else (np.empty(0, np.int64), np.empty(0, np.uint8), np.empty(0, np.uint8))
        )
        summary = {"t_us": t_us, "edge": edge, "id": channel, "counts": np.array(counts, np.int64)}
        try:
            with atomic_file(self._summary_path(key)) as fh:
                np.savez(fh, **summary)
        except OSError:
            pass  # a read-only cache: decoded again next time
        return summary

    def _trigger_summary(self) -> dict[str, np.ndarray]:
        """The triggers (t [us], edge, id) and the decoder's counts (outside, skipped) of a `.raw`:
        from the cache (its zip checksums checked), else decoded again (events not kept)."""
        if self._summary is not None:
            return self._summary
        if self.kind == ".dat":
            self._summary = {
                "t_us": np.empty(0, np.int64),
                "edge": np.empty(0, np.uint8),
                "id": np.empty(0, np.uint8),
                "counts": np.zeros(2, np.int64),
            }
            return self._summary
        key = self._key()
        try:
            with np.load(self._summary_path(key)) as kept:
                summary = {name: kept[name] for name in ("t_us", "edge", "id", "counts")}
            if (
                len({len(summary["t_us"]), len(summary["edge"]), len(summary["id"])}) == 1
                and len(summary["counts"]) == 2
            ):
                self._summary = summary
                return summary
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            pass
        triggers: list = []
        for _ in self._decoded(triggers):
            pass
        self._summary = self._save_summary(key, triggers)
        return self._summary

    # -- plugin contract ---------------------------------------------------------------------

    def contents(self) -> list[str]:
        width, height = self._size_px
        header = self.header.fields
        if self.kind == ".raw":
            told = "; ".join(f"{k} {header[k]}" for k in ("format", "evt", "geometry") if k in header)
            order = ", legacy word order" if self.legacy else ""
            lines = [f"format {DECODERS[self.format].title}{order} (.raw; header: {told})"]
        else:
            version = f", version {header['Version']}" if "Version" in header else ""
            lines = [f"format DAT of {self.format} records{version}"]
        lines.append(f"sensor {width}x{height} px (from {self._size_source})")
        lines.append(f"events {len(self.events())}")
        if self.kind == ".raw":
            s = self._trigger_summary()
            edge = s["edge"]
            channels = ", ".join(map(str, np.unique(s["id"]))) or "none"
            lines.append(
                f"external triggers {len(edge)} edges ({int(np.sum(edge == 1))} rising, {int(np.sum(edge == 0))} "
                f"falling; channels {channels})"
            )
            outside, skipped = (int(v) for v in s["counts"])
            if outside:
                lines.append(f"dropped {outside} events outside the sensor")
            if skipped:
                lines.append(f"skipped {skipped} events before the first time word (or row)")
        return lines

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A path ending in `.raw` or `.dat` whose first line is a `% ` header line."""
        path = Path(location)
        return path.suffix.lower() in (".raw", ".dat") and has_header(path)
