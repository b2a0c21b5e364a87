"""A recording, or a window of it, written in the Event Camera Dataset text layout (`convert`, for
`eas-vo convert`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo import registry
from eas_vo.config import ResolvedConfig
from eas_vo.datasets.recording import recording_clock_problems
from eas_vo.errors import EasVoError
from eas_vo.io.outputs import output_folder
from eas_vo.types import ImuSeries, PoseSeries, search_times


@dataclass(frozen=True)
class Converted:
    """What `convert` wrote: counts of each stream, the time span of its frames (or samples)
    [s], the sensor size [px] (which an event-only folder, without frames to read it from,
    must be opened with: dataset.width, dataset.height), the dataset's label, and what its
    reader tolerated (--lenient)."""

    label: str
    sensor: tuple[int, int]
    frames: int
    events: int
    imu: int
    poses: int
    span_s: float
    warnings: tuple[str, ...] = ()


def convert(config: ResolvedConfig, out: str | Path, progress: bool = False, replace: bool = False) -> Converted:
    """Write `config.run.dataset` in the Event Camera Dataset layout into `out` (one writer,
    moved into place whole: io.output_folder; an existing output only if `replace`).

    The window `run.start_s`/`run.duration_s` (Dataset.window) selects the frames (for an
    event-only stream, no frames are written: its samples are the reader's to make again);
    the events are kept from the time of the frame before the window's first (the recording's
    start if none) to that of the frame after its last (its end if none), so a full window
    keeps everything and a part what the frontends read of its first frame's past; IMU
    readings and poses over the same span, and one more at each end (to interpolate at
    every frame), each on its own clock. A stream whose clock cannot be in seconds
    (recording_clock_problems) is refused first.
    """
    from tqdm import tqdm

    from eas_vo.datasets.ecd import write_ecd_folder

    rc = config.run
    dataset = registry.open_dataset(rc.dataset, config.dataset)
    has_frames = dataset.load_frame(0) is not None
    clocks = recording_clock_problems(dataset, has_frames)  # before an event-only stream is sampled
    if clocks:
        raise EasVoError(next(iter(clocks.values())))
    window = dataset.window(rc.start_s, rc.duration_s)
    if len(window) == 0:
        raise EasVoError(
            f"{dataset.label}: the window start={rc.start_s} s, duration={rc.duration_s} s holds no sample"
        )
    times = dataset.frame_times()
    t_lo, t_hi = _kept_span(times, window)
    lo, hi = search_times(dataset.events(), [t_lo, t_hi])
    events = dataset.events()[lo:hi]
    if len(events) and events["t"][0] < 0:
        raise EasVoError(
            f"{dataset.label}: its events start at {events['t'][0]:.9f} s; events.txt cannot hold negative times"
        )
    imu = None if dataset.imu is None else _imu_within(dataset.imu, t_lo, t_hi)
    poses = None if dataset.ground_truth is None else _poses_within(dataset.ground_truth, t_lo, t_hi)
    frames = None
    if has_frames:
        frames = (
            dataset.load_frame(int(k))
            for k in tqdm(window, disable=not progress, unit="frame", desc=f"convert {dataset.label}")
        )
    with output_folder(out, replace, keep_partial=False) as staging:
        write_ecd_folder(staging, dataset.camera, times[window], frames, events, poses, imu, dataset.clock_origin_ns)
    return Converted(
        label=dataset.label,
        sensor=(dataset.camera.width, dataset.camera.height),
        frames=len(window) if has_frames else 0,
        events=len(events),
        imu=0 if imu is None else len(imu.t),
        poses=0 if poses is None else len(poses.t),
        span_s=float(times[window[-1]] - times[window[0]]),
        warnings=tuple(dataset.data_warnings()),
    )


def _kept_span(times: np.ndarray, window: np.ndarray) -> tuple[float, float]:
    """[t_lo, t_hi) [s]: from the time of the frame before the window (-inf without one) to that
    of the frame after it (+inf without one)."""
    first, last = int(window[0]), int(window[-1])
    t_lo = float(times[first - 1]) if first > 0 else -math.inf
    t_hi = float(times[last + 1]) if last + 1 < len(times) else math.inf
    return t_lo, t_hi


def _rows_around(t: np.ndarray, t_lo: float, t_hi: float) -> slice:
    """The rows of sorted times `t` [s] within [t_lo, t_hi), and the one before and the one
    after, so that poses and rates interpolate at every kept frame."""
    return slice(max(int(np.searchsorted(t, t_lo)) - 1, 0), int(np.searchsorted(t, t_hi)) + 1)


def _imu_within(imu: ImuSeries, t_lo: float, t_hi: float) -> ImuSeries:
    keep = _rows_around(imu.t, t_lo, t_hi)
    return ImuSeries(imu.t[keep], imu.acc[keep], imu.gyro[keep])


def _poses_within(poses: PoseSeries, t_lo: float, t_hi: float) -> PoseSeries:
    keep = _rows_around(poses.t, t_lo, t_hi)
    return PoseSeries(poses.t[keep], poses.p_w_c[keep], poses.q_w_c[keep])
