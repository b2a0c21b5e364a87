"""AEDAT4 recordings (iniVation's DV software), decoded by datasets/aedat4_packets.py (not by
dv-processing, which spins or crashes on a damaged packet): events on both cores, frames, IMU
and the sensor size.

From the file: the `events` stream (x, y, polarity, microsecond timestamps), the `frames`
stream (APS frames with their start-of-exposure timestamp and exposure duration), the `imu`
stream (accelerometer in g, gyro in deg/s) and the sensor size. An AEDAT4 holds no lens
calibration and no ground truth: `dataset.calibration` names a calibration file (any format of
datasets/calibration.py) and `dataset.ground_truth` a TUM file (`t px py pz qx qy qz qw`,
camera-to-world).

Time: microseconds on the camera's clock -> float64 seconds. A frame's time is the middle of
its exposure (start + exposure / 2), the instant the DAVIS ROS driver, and so the Event Camera
Dataset and the `ecd` reader, gives a frame; units: g -> m/s^2 (standard gravity), deg/s -> rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from eas_vo.concurrency import in_order
from eas_vo.datasets.aedat4_packets import MAGIC, Aedat4File, DvFrame, Scratch
from eas_vo.datasets.recording import CALIBRATION_FORMATS, RecordingReader, StreamConfig, clock_origin_ns
from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, cache_key, file_identity, load_cached
from eas_vo.eventfile.kernels import check_and_pack_dv
from eas_vo.io.tables import check_increasing
from eas_vo.types import EVENT_DTYPE, ImuSeries, empty_events

#: Standard gravity [m/s^2]: the g of accelerometer datasheets, in which DV stores readings.
STANDARD_GRAVITY = 9.80665


@dataclass(frozen=True)
class Aedat4Config(StreamConfig):
    """StreamConfig; `calibration` is required (an AEDAT4 file holds no lens calibration)."""


def is_aedat4(path: Path) -> bool:
    """Whether `path` is a file starting with the AEDAT 4.0 magic bytes (never raises)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(MAGIC)) == MAGIC
    except (OSError, ValueError):  # ValueError: a NUL in the name
        return False


#: Compressed bytes of event packets decoded as one task: several milliseconds of work, so
#: that handing tasks between threads costs little (docs/speed.md, "Recordings in other formats").
GROUP_BYTES = 1 << 20
#: Groups decoded ahead of the one being written (bounded memory).
GROUPS_AHEAD = 6


def _groups(sizes: list[int], group_bytes: int) -> list[range]:
    """Consecutive packet indices cut into groups of about `group_bytes` (at least one packet each)."""
    groups, start, total = [], 0, 0
    for k, size in enumerate(sizes):
        total += size
        if total >= group_bytes:
            groups.append(range(start, k + 1))
            start, total = k + 1, 0
    if start < len(sizes):
        groups.append(range(start, len(sizes)))
    return groups


class _Slot:
    """A group's reused buffers: the decompression scratch and the packed records."""

    def __init__(self):
        self.scratch = Scratch()
        self.packed = np.empty(0, EVENT_DTYPE)

    def room(self, rows: int) -> np.ndarray:
        """The packed records' buffer with room for `rows` (the rows already there kept)."""
        if len(self.packed) < rows:
            grown = np.empty(max(rows, 2 * len(self.packed)), EVENT_DTYPE)
            grown[: len(self.packed)] = self.packed
            self.packed = grown
        return self.packed


class Aedat4Dataset(RecordingReader):
    """An AEDAT4 recording of a DAVIS (or any DV camera): events, frames, IMU."""

    name = "aedat4"
    description = "AEDAT4 recording (iniVation DV): events, frames, IMU; --set dataset.calibration=FILE"
    Config = Aedat4Config

    def __init__(self, location: str | Path, config: Aedat4Config | None = None):
        self.config = config or Aedat4Config()
        self.path = Path(location)
        self.label = str(self.path)
        self.warnings = DataWarnings()
        if not self.path.is_file():
            raise DataError(self.path, "AEDAT4 file not found")
        if not is_aedat4(self.path):
            raise DataError(self.path, f"not an AEDAT4 file (it does not start with {MAGIC.decode().strip()!r})")
        self.file = Aedat4File(self.path)
        self.clock_origin_ns = clock_origin_ns(self._first_time_us() * 1000)
        self._origin_us = self.clock_origin_ns // 1000
        self._sensor = width, height = self._sensor_size()
        self.camera = self.calibration_file(width, height)
        if self.camera is None:
            self.no_camera_reason = (
                f"{self.path}: an AEDAT4 file holds no lens calibration: give one with --set "
                f"dataset.calibration=FILE ({CALIBRATION_FORMATS})"
            )
        self._frame_times = self._read_frame_times()
        self._times = self._frame_times
        if self._frame_times is None:
            self.no_frames_reason = f"{self.path} has no frames stream (an event-only recording)"
        self.imu = self._read_imu()
        self.ground_truth = self.ground_truth_file()
        self._events: np.ndarray | None = None

    def _first_time_us(self) -> int:
        """The first event's timestamp [us], else the first frame's, else the first IMU reading's
        (0 with none): its whole second is the clock origin, whichever stream gives it."""
        streams = self.file.streams
        if "events" in streams and streams["events"].packets:
            records = self.file.event_records(0)
            if len(records):
                return int(records["t"][0])
        if "frames" in streams and streams["frames"].packets:
            return int(self.file.frame(0).start_us)
        if "imu" in streams:  # (an IMU-only file: its rows are read once more by _read_imu)
            rows = self.file.imu_rows()
            return int(rows[0, 0]) if len(rows) else 0
        return 0

    def _sensor_size(self) -> tuple[int, int]:
        """(width, height) [px] from the events' or the frames' stream description (equal if both)."""
        sizes = {kind: self.file.streams[kind].size for kind in ("events", "frames") if kind in self.file.streams}
        sizes = {kind: size for kind, size in sizes.items() if size is not None}
        if not sizes:
            raise DataError(
                self.path, "neither an events nor a frames stream with a resolution: the sensor size is unknown"
            )
        if len(set(sizes.values())) > 1:
            raise DataError(
                self.path,
                "the events stream is {0[0]}x{0[1]} px, the frames stream {1[0]}x{1[1]}".format(
                    sizes["events"], sizes["frames"]
                ),
            )
        return next(iter(sizes.values()))

    # -- frames --------------------------------------------------------------------------

    def _read_frame_times(self) -> np.ndarray | None:
        """Frame times [s] (mid-exposure) of the frames kept, None without frames; frames going
        back in time are errors (dropped and counted with --lenient). Notes each kept frame's
        packet."""
        if "frames" not in self.file.streams:
            return None
        where = f"{self.path}:frames"
        middles, self._frame_index = [], []
        for index in range(len(self.file.streams["frames"].packets)):
            frame = self.file.frame(index)
            middle_us = frame.start_us + frame.exposure_us / 2
            if middles and middle_us < middles[-1]:
                if not self.config.lenient:
                    raise DataError(
                        where, f"frame time {middle_us / 1e6:.6f} s goes back (previous {middles[-1] / 1e6:.6f})", index
                    )
                self.warnings.add(where, "frame time going back", f"frame {index}")
                continue
            self._check_frame(frame, index)
            middles.append(middle_us)
            self._frame_index.append(index)
        return (np.array(middles) - self._origin_us) / 1e6 if middles else None

    def _check_frame(self, frame: DvFrame, index: int) -> None:
        size = frame.image.shape[1], frame.image.shape[0]
        expected = self._sensor
        if size != expected or any(frame.position):
            raise DataError(
                f"{self.path}:frames",
                f"frame is {size[0]}x{size[1]} px at {frame.position}, not the {expected[0]}x{expected[1]} sensor",
                index,
            )

    def load_frame(self, k: int) -> np.ndarray | None:
        if self._frame_times is None:
            return None
        image = self.file.frame(self._frame_index[k]).image  # a view of the packet's bytes: copied
        if image.ndim == 2:
            return image.copy()
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)

    # -- IMU, events -------------------------------------------------------------------------

    def _read_imu(self) -> ImuSeries | None:
        """The imu stream in the project's units, or None without one (or with fewer than 2
        readings: nothing to interpolate between)."""
        if "imu" not in self.file.streams:
            return None
        table = self.file.imu_rows()
        if len(table) < 2:
            return None
        t = (table[:, 0] - self._origin_us) / 1e6
        keep = check_increasing(f"{self.path}:imu", t, lambda row: row, self.tolerated, "reading")
        t, table = t[keep], table[keep]
        return ImuSeries(t=t, acc=table[:, 1:4] * STANDARD_GRAVITY, gyro=np.deg2rad(table[:, 4:7]))

    def events(self) -> np.ndarray:
        if self._events is None:
            self._events = self._load_events() if "events" in self.file.streams else empty_events()
        return self._events

    def _load_events(self) -> np.ndarray:
        c = self.config
        where = f"{self.path}:events"
        packets = self.file
        width, height = self._sensor
        groups = _groups(packets.sizes, GROUP_BYTES)
        slots = [
            _Slot() for _ in range(GROUPS_AHEAD)
        ]  # in_order keeps GROUPS_AHEAD groups at most, the one taken included

        def checked(g):
            """Group g's packets decoded, each checked on its own (as if it started the stream)
            and packed, one after the other into its slot (on a worker thread: cramjam's
            decoders and the check kernel release the GIL): (the slot, per packet: (index,
            first row in the slot, rows, first bad row or -1, its last time [s]), and the
            group's (first, last) time [s] if it is valid as a whole on its own, else None)."""
            slot, verdicts, used = slots[g % len(slots)], [], 0
            first_t, latest, plain = np.inf, -np.inf, True
            for k in groups[g]:
                records = packets.event_records(k, slot.scratch)
                packed = slot.room(used + len(records))[used : used + len(records)]
                bad, last_t = check_and_pack_dv(
                    records.view(np.int64).reshape(-1, 2),
                    self._origin_us,
                    -np.inf,
                    width,
                    height,
                    c.time_tolerance_s,
                    packed,
                )
                verdicts.append((k, used, len(records), bad, last_t))
                used += len(records)
                if len(records):
                    start = packed[0]["t"]
                    plain &= bad < 0 and start >= latest
                    first_t, latest = min(first_t, start), max(latest, last_t)
            return slot, verdicts, ((first_t, latest) if plain else None)

        def fill(out, warnings):
            validate = Validator(where, width, height, c.time_tolerance_s, c.lenient, warnings, "event")
            read = kept = 0  # events in the packets before this one (the index messages name), kept
            for slot, verdicts, plain in in_order(checked, len(groups), ahead=GROUPS_AHEAD):
                if plain is not None and plain[0] >= validate.last_t:
                    # Every packet valid on its own, none starting before the one before it,
                    # nor the group before the stream so far: what the stream's check would
                    # have packed, bit for bit.
                    rows = sum(verdict[2] for verdict in verdicts)
                    out.write(slot.packed[:rows].data)
                    validate.last_t = max(validate.last_t, plain[1])
                    read, kept = read + rows, kept + rows
                    continue
                run = None  # (first, end) rows of the slot accepted as packed, not yet written
                for k, first, rows, bad, last_t in verdicts:
                    if bad < 0 and (rows == 0 or slot.packed["t"][first] >= validate.last_t):
                        # Valid on its own, and its first time not before the stream so far.
                        validate.last_t = max(validate.last_t, last_t)
                        run, kept = (run[0] if run else first, first + rows), kept + rows
                    else:
                        if run:
                            out.write(slot.packed[run[0] : run[1]].data)
                            run = None
                        records = packets.event_records(k)  # again, on its own: the stream's check row by row
                        events = validate(
                            records["t"] - self._origin_us,
                            records["x"],
                            records["y"],
                            records["p"],
                            lambda row, before=read: before + row,
                            per_second=1e6,
                        )
                        out.write(events.data)
                        kept += len(events)
                    read += rows
                if run:
                    out.write(slot.packed[run[0] : run[1]].data)
            return kept

        key = cache_key("aedat4", *file_identity(self.path), width, height, c.time_tolerance_s, self._origin_us)
        return load_cached(key, c.lenient, self.warnings, fill, where)

    # -- plugin contract ---------------------------------------------------------------

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A path ending in `.aedat4` whose first bytes are the AEDAT 4.0 magic."""
        path = Path(location)
        return path.suffix.lower() == ".aedat4" and is_aedat4(path)
