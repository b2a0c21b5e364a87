"""What a recording holds, before any long work (`describe`, for `eas-vo info`): its streams, sensor,
camera, and each stream's span, count and rate."""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from eas_vo import registry
from eas_vo.camera import CameraModel
from eas_vo.config import ResolvedConfig
from eas_vo.datasets.recording import recording_clock_problems


@dataclass(frozen=True)
class Span:
    """A timed stream: `count` items from `t0_s` to `t1_s` [s] (both NaN when empty)."""

    count: int
    t0_s: float
    t1_s: float

    @classmethod
    def of(cls, t: np.ndarray) -> "Span":
        """The span of sorted times `t` [s] (reads only their ends)."""
        return cls(len(t), float(t[0]), float(t[-1])) if len(t) else cls(0, math.nan, math.nan)

    @property
    def duration_s(self) -> float:
        return self.t1_s - self.t0_s if self.count else 0.0

    @property
    def rate_hz(self) -> float:
        """Mean rate [1/s]: intervals per second (NaN without two items some time apart)."""
        return (self.count - 1) / self.duration_s if self.count > 1 and self.duration_s > 0 else math.nan

    def text(self, what: str) -> str:
        """'1234 WHAT, 0.000-59.998 s (59.998 s), 20.6 Hz'."""
        if not self.count:
            return f"0 {what}"
        rate = f", {_si(self.rate_hz)}Hz" if math.isfinite(self.rate_hz) else ""
        return f"{self.count} {what}, {self.t0_s:.3f}-{self.t1_s:.3f} s ({self.duration_s:.3f} s){rate}"


@dataclass(frozen=True)
class SequenceInfo:
    """What `describe` found.

    Attributes:
        label, plugin: the dataset as its plugin labels it, and the plugin's name.
        sensor: sensor size (width, height) [px], None if the dataset cannot tell it.
        camera: lens model, intrinsics [px] and distortion; None when the recording holds none
            (`no_camera_reason` says what to give).
        contents: what the file holds in its own terms (Dataset.contents), one line each.
        frames: the APS frames' times, or None for an event-only stream (`no_frames_reason`
            says why), whose samples (the times it is processed at) are then `samples`.
        samples: the times the dataset yields samples at (Dataset.frame_times).
        events, imu, ground_truth: each stream's span, None when the dataset has none.
        clock_origin_ns: the recording's clock at 0 s of the spans (Dataset.clock_origin_ns).
        warnings: clocks whose unit cannot be seconds (recording_clock_problems: a run refuses
            them), then what the reader tolerated (--lenient), one line per kind.
    """

    label: str
    plugin: str
    sensor: tuple[int, int] | None
    camera: CameraModel | None
    contents: tuple[str, ...]
    frames: Span | None
    samples: Span
    no_frames_reason: str
    events: Span | None
    imu: Span | None
    ground_truth: Span | None
    no_camera_reason: str = ""
    clock_origin_ns: int = 0
    warnings: tuple[str, ...] = ()

    @property
    def span(self) -> Span:
        """From the earliest item of any stream to the latest [s] (count: the streams)."""
        spans = [s for s in (self.samples, self.events, self.imu, self.ground_truth) if s is not None and s.count]
        if not spans:
            return Span(0, math.nan, math.nan)
        return Span(len(spans), min(s.t0_s for s in spans), max(s.t1_s for s in spans))

    def overlaps(self) -> list[str]:
        """One phrase per pair of streams: how much of the samples' span (frames, or samples from
        the events) each other stream covers, then of the ground truth's; a stream that covers
        none of it is said to, with both spans and the setting that moves its clock."""
        hints = {
            "events": "the events' clock is not the frames'",
            "IMU": "run.imu_time_offset_s",
            "ground truth": "dataset.ground_truth_time_offset_s",
        }
        bases = [
            ("frames" if self.frames is not None else "samples", self.samples),
            ("ground truth", self.ground_truth),
        ]
        others = [
            ("events", self.events),
            ("IMU", self.imu),
            ("ground truth", self.ground_truth),
            (bases[0][0], self.samples),
        ]
        lines = []
        for base_name, base in bases:
            if base is None or not base.count:
                continue
            out = []
            for name, other in others:
                if name == base_name or other is None or not other.count:
                    continue
                covered = max(0.0, min(base.t1_s, other.t1_s) - max(base.t0_s, other.t0_s))
                if base.duration_s > 0 and covered > 0:
                    out.append(f"{name} {covered:.3f} s ({100 * covered / base.duration_s:.0f} %)")
                elif base.t0_s <= other.t1_s and other.t0_s <= base.t1_s:
                    out.append(f"{name} all")
                else:
                    hint = hints["ground truth"] if "ground truth" in (name, base_name) else hints.get(name, "")
                    out.append(
                        f"{name} NONE ({other.t0_s:.3f}-{other.t1_s:.3f} s against {base.t0_s:.3f}-{base.t1_s:.3f} s: "
                        f"another clock? {hint})"
                    )
            if out:
                lines.append(f"of the {base_name}: {'; '.join(out)}")
        return lines

    def missing(self) -> list[str]:
        """What a run would need that the recording does not give, one line each."""
        out = []
        if self.camera is None:
            out.append(self.no_camera_reason)
        if self.frames is None:
            out.append("no frames: only an event tracker runs on it (--tracker cmax)")
        if self.ground_truth is None:
            out.append("no ground truth: runs are not scored (--set dataset.ground_truth=poses.tum)")
        elif not self.ground_truth.count or (
            self.samples.count
            and (self.ground_truth.t1_s < self.samples.t0_s or self.ground_truth.t0_s > self.samples.t1_s)
        ):
            out.append("the ground truth overlaps none of the samples: runs cannot be scored")
        return out

    def lines(self) -> list[str]:
        """The report `eas-vo info` prints: what the file holds, then what a run would miss."""
        present = [
            name
            for name, s in (
                ("frames", self.frames),
                ("events", self.events),
                ("IMU", self.imu),
                ("ground truth", self.ground_truth),
            )
            if s is not None and s.count
        ]
        span = self.span
        out = [f"{self.label} (dataset plugin {self.plugin})"]
        out += [f"  file          {line}" for line in self.contents]
        out.append(f"  streams       {', '.join(present) or 'none'}")
        out.append(
            f"  sensor        {self.sensor[0]} x {self.sensor[1]} px" if self.sensor else "  sensor        unknown"
        )
        if self.camera is not None:
            c = self.camera
            fx, fy, cx, cy = c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2]
            dist = ", ".join(f"{v:.6g}" for v in c.dist)
            out.append(
                f"  camera        {c.model} lens: fx {fx:.6g} fy {fy:.6g} cx {cx:.6g} cy {cy:.6g} px, distortion [{dist}]"
            )
        else:
            out.append("  camera        unknown (no calibration)")
        if self.clock_origin_ns:
            when = datetime.fromtimestamp(self.clock_origin_ns // 10**9, timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
            out.append(
                f"  clock         times below are after {self.clock_origin_ns // 10**9} s of the recording's clock "
                f"({when} as Unix time); files written add it back"
            )
        out.append(
            f"  duration      {span.duration_s:.3f} s ({span.t0_s:.3f}-{span.t1_s:.3f} s, all streams)"
            if span.count
            else "  duration      0 s (no stream holds anything)"
        )
        if self.frames is not None:
            out.append(f"  frames        {self.frames.text('APS frames')}")
        else:
            out.append(f"  frames        none: {self.no_frames_reason}")
            out.append(f"  samples       {self.samples.text('samples from the events')}")
        if self.events is None or not self.events.count:
            out.append("  events        none")
        else:
            e = self.events
            rate = f", {_si(e.count / e.duration_s).rstrip()} events/s" if e.duration_s > 0 else ""
            out.append(f"  events        {e.count} events, {e.t0_s:.3f}-{e.t1_s:.3f} s ({e.duration_s:.3f} s){rate}")
        out.append(f"  IMU           {self.imu.text('readings') if self.imu is not None else 'none'}")
        out.append(f"  ground truth  {self.ground_truth.text('poses') if self.ground_truth is not None else 'none'}")
        out += [f"  overlap       {line}" for line in self.overlaps()]
        out += [f"  warning       {line}" for line in self.warnings]
        out += [f"  to run        {line}" for line in self.missing()]
        return out


def _si(value: float) -> str:
    """A rate with an SI prefix and the space before the unit: '20.6 ', '1.23 M'."""
    for prefix, scale in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(value) >= scale:
            return f"{value / scale:.3g} {prefix}"
    return f"{value:.3g} "


def describe(config: ResolvedConfig) -> SequenceInfo:
    """Open `config.run.dataset` (with the [dataset] settings) and say what it holds. Reads
    the frame list and at most one frame (whether there are frames at all), and the event
    stream once (its first read caches it)."""
    dataset = registry.open_dataset(config.run.dataset, config.dataset, need_camera=False)
    has_frames = dataset.load_frame(0) is not None
    clocks = recording_clock_problems(dataset, has_frames)
    events = dataset.events()
    # an event-only stream's samples are made from its events: not from a clock in the wrong unit
    unsampled = not has_frames and "event" in clocks
    samples = np.empty(0) if unsampled else dataset.frame_times()
    has_frames = has_frames and len(samples) > 0
    return SequenceInfo(
        label=dataset.label,
        plugin=type(dataset).name,
        sensor=dataset.sensor_size,
        camera=dataset.camera,
        contents=tuple(dataset.contents()),
        no_camera_reason="" if dataset.camera is not None else dataset.no_camera_reason,
        clock_origin_ns=dataset.clock_origin_ns,
        frames=Span.of(samples) if has_frames else None,
        samples=Span.of(samples),
        no_frames_reason="" if has_frames else dataset.no_frames_reason,
        events=Span.of(events["t"]) if len(events) else None,
        imu=None if dataset.imu is None else Span.of(dataset.imu.t),
        ground_truth=None if dataset.ground_truth is None else Span.of(dataset.ground_truth.t),
        warnings=(*clocks.values(), *dataset.data_warnings()),
    )
