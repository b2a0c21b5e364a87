"""What the recording readers (`ecd`, the bag readers, `aedat4`, `mvsec`) share: their reading
options, checks of timed tables, TUM ground-truth files, and the sampling of event-only streams.
Not a plugin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.datasets.calibration import read_calibration
from eas_vo.errors import DataWarnings
from eas_vo.io.tum import read_tum
from eas_vo.plugins import Dataset
from eas_vo.types import TIME_UNITS, PoseSeries
from eas_vo.validation import check_range


@dataclass(frozen=True)
class StreamConfig:
    """How to read a recording.

    Attributes:
        lenient: drop malformed lines and out-of-order or out-of-sensor events with counted
            warnings instead of stopping at the first.
        time_tolerance_s: event timestamps may step back this much [s] (clamped); more is an error.
        sample_rate_hz: event-only streams: samples per second...
        sample_every_events: ...or, when > 0, one sample every this many events.
        calibration: a calibration file (CALIBRATION_FORMATS) used instead of what the
            recording holds (a bag's CameraInfo, an ECD calib.txt); required where it holds none.
        calibration_camera: which camera of that file (a kalibr `camN`, a DV XML camera node);
            empty: the reader's choice (cam0, or the only one).
        ground_truth: a TUM file of camera-to-world poses (`t px py pz qx qy qz qw`) used instead
            of what the recording holds; empty: the recording's own, if any.
        ground_truth_time_offset_s: added to the ground truth's times to put them on the
            recording's clock [s] (a ground truth from 0 beside a Unix-time recording).
    """

    lenient: bool = False
    time_tolerance_s: float = 1e-6
    sample_rate_hz: float = 20.0
    sample_every_events: int = 0
    calibration: str = ""
    calibration_camera: str = ""
    ground_truth: str = ""
    ground_truth_time_offset_s: float = 0.0

    def validate(self) -> None:
        check_range(self, "time_tolerance_s", 0.0, 1.0)
        check_range(self, "sample_rate_hz", 0.0, 1e6, lo_open=True)
        check_range(self, "sample_every_events", 0, 10**9)
        check_range(self, "ground_truth_time_offset_s", -1e10, 1e10)


#: A clock whose first time lies within this of zero [s] is read as it is: float64 seconds keep
#: 0.12 ns up to 1e6 s (11.6 days). Beyond it (Unix time), times are read after an origin.
ORIGIN_FREE_S = 1e6


def clock_origin_ns(first_ns: int) -> int:
    """The clock origin [ns] (Dataset.clock_origin_ns) for a recording whose first time is
    `first_ns` [ns]: 0 within ORIGIN_FREE_S of zero, else that time's whole second (so that
    relative times keep the recording's own sub-second digits)."""
    first_ns = int(first_ns)
    return 0 if abs(first_ns) < ORIGIN_FREE_S * 1e9 else first_ns // 1_000_000_000 * 1_000_000_000


#: Two streams of one recording whose time spans differ by this factor or more do not count
#: time in one unit: an excerpt may keep a few milliseconds of one stream beside tens of
#: seconds of another (a few ms of events beside 30 s would be 1e4; docs/time_offsets.md,
#: "Every clock in seconds"), while a stream in microseconds beside one in seconds spans 1e6
#: times as long, in nanoseconds 1e9.
SPAN_RATIO_LIMIT = 1e5
#: No recording's stream lasts longer than a day [s]: a longer span is a clock read in a
#: smaller unit than seconds (60 s in microseconds span 6e7 "s").
MAX_SPAN_S = 86400.0
#: Events and frames further apart than this many times the longer one's span (or a second)
#: are on two clocks: an excerpt cuts a stream short, it does not move it (Unix time beside a
#: clock from zero: 1.7e9 s apart).
STREAMS_APART_SPANS = 100.0
#: The units of TIME_UNITS a span ratio can tell from seconds (milliseconds cannot: excerpts'
#: streams may differ by that much).
SMALL_UNITS = {unit: factor for unit, factor in TIME_UNITS.items() if factor >= SPAN_RATIO_LIMIT}


def _unit_of(ratio: float) -> str:
    """The unit of SMALL_UNITS whose factor is nearest `ratio` (in orders of magnitude)."""
    return min(SMALL_UNITS, key=lambda unit: abs(np.log10(ratio / SMALL_UNITS[unit])))


def clock_unit_problems(spans: dict[str, float], sources: dict[str, str]) -> dict[str, str]:
    """Stream name -> one line, for each stream whose time span [s] cannot be in seconds beside
    the others'.

    `spans`: stream name -> the span of its times [s] (last minus first: whatever the clock's
    origin); `sources`: stream name -> where its times are read (a file, an HDF5 dataset), for
    the message. A stream whose span differs from the reference's (the median span: the odd
    one out when three or more streams agree, else the shorter; the frames' when they agree with
    it) by SPAN_RATIO_LIMIT or more is
    named with the unit the ratio suggests; else one spanning more than MAX_SPAN_S (alone, or
    beside streams as long)."""
    problems, kept = {}, {name: span for name, span in spans.items() if span > 0}
    if not kept:
        return problems
    ordered = sorted(kept, key=kept.get)
    reference = ordered[(len(ordered) - 1) // 2]
    if "frame" in kept and 1 / SPAN_RATIO_LIMIT < kept["frame"] / kept[reference] < SPAN_RATIO_LIMIT:
        reference = "frame"  # the clock every time is put on (docs/time_offsets.md), when it agrees
    ref_span, ref_where = kept[reference], sources.get(reference, reference)
    for name in ordered:
        ratio = kept[name] / ref_span
        against = f"the {reference} timestamps' {ref_span:.4g} s ({ref_where})"
        if ratio >= SPAN_RATIO_LIMIT:
            problems[name] = (
                f"{sources.get(name, name)}: the {name} timestamps span {kept[name]:.4g} s, {ratio:.3g} times "
                f"{against}: they look like {_unit_of(ratio)}; times must be in seconds"
            )
        elif ratio <= 1 / SPAN_RATIO_LIMIT:
            problems[name] = (
                f"{sources.get(name, name)}: the {name} timestamps span {kept[name]:.4g} s, 1/{1 / ratio:.3g} "
                f"of {against}: those look like {_unit_of(1 / ratio)}; times must be in seconds"
            )
        elif kept[name] > MAX_SPAN_S:
            problems[name] = (
                f"{sources.get(name, name)}: the {name} timestamps span {kept[name]:.4g} s, more than a day, "
                f"which no recording lasts: they look like microseconds ({kept[name] / 1e6:.4g} s) or "
                f"nanoseconds ({kept[name] / 1e9:.4g} s); times must be in seconds"
            )
    return problems


def recording_clock_problems(dataset: Dataset, has_frames: bool) -> dict[str, str]:
    """clock_unit_problems of `dataset`'s streams: its frames (when `has_frames`: an event-only
    stream's samples are made from its events, and are not read here), events, IMU and ground
    truth, each named by time_source; and events lying far from the frames (STREAMS_APART_SPANS:
    a stream on another clock). Reads the event stream (Dataset.events)."""
    events = dataset.events()
    streams = {
        "frame": dataset.frame_times() if has_frames else None,
        "event": events["t"] if len(events) else None,
        "IMU": None if dataset.imu is None else dataset.imu.t,
        "ground-truth": None if dataset.ground_truth is None else dataset.ground_truth.t,
    }
    spans = {name: float(t[-1]) - float(t[0]) for name, t in streams.items() if t is not None and len(t) > 1}
    problems = clock_unit_problems(spans, {name: time_source(dataset, name) for name in spans})
    frames, event_t = streams["frame"], streams["event"]
    if not problems and frames is not None and len(frames) and event_t is not None:
        first, last = float(event_t[0]), float(event_t[-1])
        apart = max(float(frames[0]) - last, first - float(frames[-1]))
        if apart > STREAMS_APART_SPANS * max(last - first, float(frames[-1]) - float(frames[0]), 1.0):
            problems["event"] = (
                f"{time_source(dataset, 'event')}: the events ({first:.6g} to {last:.6g} s) and the frames "
                f"({float(frames[0]):.6g} to {float(frames[-1]):.6g} s, {time_source(dataset, 'frame')}) "
                "do not overlap: are they on two clocks (one from zero, one at Unix time)? "
                "Every time must be on the recording's one clock"
            )
    return problems


def time_source(dataset: Dataset, stream: str) -> str:
    """Where `dataset`'s `stream` ("frame", "event", "IMU", "ground-truth") is read, for
    messages: a RecordingReader's time_sources, else the dataset's label and the stream."""
    sources = dataset.time_sources() if isinstance(dataset, RecordingReader) else {}
    return sources.get(stream, f"{dataset.label} ({stream} stream)")


def event_sample_times(event_t: np.ndarray, rate_hz: float, every_events: int) -> np.ndarray:
    """Sample times [s] for an event-only stream: every `every_events` events, else at `rate_hz`."""
    if len(event_t) == 0:
        return np.empty(0)
    if every_events > 0:
        return np.unique(np.asarray(event_t[::every_events], dtype=float))
    return np.arange(float(event_t[0]), float(event_t[-1]), 1.0 / rate_hz)


#: Calibration formats, for messages.
CALIBRATION_FORMATS = "a DV calibration XML, a kalibr camchain YAML, a ROS camera_info YAML or an ECD calib.txt"


class RecordingReader(Dataset):
    """What the recording readers' plugins share: `data_warnings` from their `warnings`
    (DataWarnings) and, for an event-only stream (`_times` None), frame times sampled from the
    events at the config's `sample_rate_hz` or every `sample_every_events`."""

    warnings: DataWarnings
    _times: np.ndarray | None
    _sensor: tuple[int, int]
    config: StreamConfig

    @property
    def sensor_size(self) -> tuple[int, int]:
        """(width, height) [px], known with or without a calibration."""
        return self._sensor

    def calibration_file(
        self, width: int | None, height: int | None, default_camera: str | None = None
    ) -> CameraModel | None:
        """The camera of `config.calibration` for a width x height [px] sensor, or None when no
        file is given (`default_camera`: the camera read when `calibration_camera` is empty)."""
        c = self.config
        if not c.calibration:
            return None
        return read_calibration(
            c.calibration, width=width, height=height, camera=c.calibration_camera or default_camera
        )

    def ground_truth_file(self) -> PoseSeries | None:
        """The poses of `config.ground_truth` (a TUM file) on the recording's clock (after its
        clock_origin_ns), or None."""
        c = self.config
        if not c.ground_truth:
            return None
        return read_tum(
            c.ground_truth,
            c.ground_truth_time_offset_s,
            self.clock_origin_ns,
            self.tolerated,
            min_poses=2,
            what="ground truth",
        )

    @property
    def tolerated(self) -> DataWarnings | None:
        """Where what --lenient tolerates is counted (`warnings`), or None when reading strictly."""
        return self.warnings if self.config.lenient else None

    def data_warnings(self) -> list[str]:
        return self.warnings.lines()

    def time_sources(self) -> dict[str, str]:
        """Where each stream's times are read ("frame", "event", "IMU", "ground-truth" -> a
        file, an HDF5 dataset, a stream), for messages: by default the recording's label and
        the stream, and config.ground_truth when it gives the ground truth."""
        sources = {name: f"{self.label} ({name} stream)" for name in ("frame", "event", "IMU", "ground-truth")}
        if self.config.ground_truth:
            sources["ground-truth"] = self.config.ground_truth
        return sources

    def frame_times(self) -> np.ndarray:
        if self._times is None:  # event-only: samples from the events
            c = self.config
            self._times = event_sample_times(self.events()["t"], c.sample_rate_hz, c.sample_every_events)
        return self._times
