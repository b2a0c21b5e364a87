"""The plugin protocols: what a dataset, a frontend and a backend provide.

A plugin class has a `name`, a one-line `description`, a frozen dataclass
`Config`, and is built from that config. Register it under the entry-point
group `eas_vo.datasets`, `eas_vo.frontends` or `eas_vo.backends`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Sequence

import numpy as np

from eas_vo.types import CameraModel, ImuSeries, PoseSeries, RelativeRotation, Sample, search_times


@dataclass(frozen=True)
class NoConfig:
    """A plugin without options."""


class Dataset:
    """A recording: frames and events in time order, camera model, optional ground truth and IMU.

    Subclasses set `camera`, `ground_truth`, `imu`, `description` and implement
    `frame_times()`, `load_frame(k)` and `events()`.
    """

    name = "dataset"
    description = ""
    Config = NoConfig
    camera: CameraModel
    ground_truth: PoseSeries | None = None
    imu: ImuSeries | None = None
    no_frames_reason = "the dataset has no APS frames"

    def frame_times(self) -> np.ndarray:
        """(N,) frame timestamps [s], increasing."""
        raise NotImplementedError

    def load_frame(self, k: int) -> np.ndarray | None:
        """Grayscale uint8 frame k, or None for an event-only stream."""
        raise NotImplementedError

    def events(self) -> np.ndarray:
        """The whole event stream as EVENT_DTYPE (possibly memory-mapped), sorted by time."""
        raise NotImplementedError

    def window(self, start_s: float = 0.0, duration_s: float = np.inf) -> np.ndarray:
        """Indices of the frames in [t0 + start_s, t0 + start_s + duration_s), t0 the first frame time."""
        times = self.frame_times()
        if len(times) == 0:
            return np.arange(0)
        lo = times[0] + start_s
        return np.flatnonzero((times >= lo) & (times < lo + duration_s))

    def samples(self, start_s: float = 0.0, duration_s: float = np.inf) -> Iterator[Sample]:
        """Yield the samples of the window, each with a view of the event stream."""
        indices = self.window(start_s, duration_s)
        if len(indices) == 0:
            return
        events = self.events()
        times = self.frame_times()
        starts = search_times(events, times[indices])
        first_k = int(indices[0])
        prev = int(search_times(events, times[first_k - 1])[0]) if first_k > 0 else 0
        for n, (k, first) in enumerate(zip(indices, starts)):
            yield Sample(
                index=n,
                t=float(times[k]),
                frame=self.load_frame(int(k)),
                events=events,
                event_index=int(first),
                prev_event_index=prev,
            )
            prev = int(first)


class Frontend:
    """Turns a Sample into one grayscale uint8 image of sensor size.

    Stateful frontends consume `sample.events_since_previous` incrementally;
    `reset()` clears their state.
    """

    name = "frontend"
    description = ""
    Config = NoConfig
    needs_frames = False

    def __init__(self, config=None, camera: CameraModel | None = None):
        self.config = config if config is not None else self.Config()
        self.camera = camera

    def reset(self) -> None:
        """Forget any state accumulated from earlier samples."""

    def __call__(self, sample: Sample) -> np.ndarray:
        raise NotImplementedError


class Backend:
    """Turns relative rotations into absolute camera-to-world rotations (R_w_c per frame)."""

    name = "backend"
    description = ""
    Config = NoConfig

    def __init__(self, config=None):
        self.config = config if config is not None else self.Config()

    def solve(self, n_frames: int, edges: Sequence[RelativeRotation], times=None, imu: ImuSeries | None = None) -> np.ndarray:
        """(n_frames, 3, 3) rotations R_w_c with frame 0 at the identity, from the measured
        edges and, where useful, the frame times [s] and the dataset's IMU."""
        raise NotImplementedError
