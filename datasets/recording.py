"""What the recording readers (`ecd`, the bag readers) share: their reading options, checks of
timed tables, and the sampling of event-only streams. Not a plugin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.errors import DataError
from eas_vo.types import PoseSeries
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
    """

    lenient: bool = False
    time_tolerance_s: float = 1e-6
    sample_rate_hz: float = 20.0
    sample_every_events: int = 0

    def validate(self) -> None:
        check_range(self, "time_tolerance_s", 0.0, 1.0)
        check_range(self, "sample_rate_hz", 0.0, 1e6, lo_open=True)
        check_range(self, "sample_every_events", 0, 10**9)


def event_sample_times(event_t: np.ndarray, rate_hz: float, every_events: int) -> np.ndarray:
    """Sample times [s] for an event-only stream: every `every_events` events, else at `rate_hz`."""
    if len(event_t) == 0:
        return np.empty(0)
    if every_events > 0:
        return np.unique(np.asarray(event_t[::every_events], dtype=float))
    return np.arange(float(event_t[0]), float(event_t[-1]), 1.0 / rate_hz)


def _row_number(row: int) -> int:
    return row + 1


def check_increasing(where: str, t: np.ndarray, line_of=_row_number) -> None:
    """Raise DataError naming the first row whose time [s] does not increase; `line_of(row)`
    turns a row index into what the message names (a file line; default: the row from 1)."""
    bad = np.flatnonzero(np.diff(t) <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        raise DataError(where, f"timestamp {t[i]:.9f} does not increase (previous {t[i - 1]:.9f})", line_of(i))


def pose_series(where: str, table: np.ndarray, line_of=_row_number) -> PoseSeries:
    """`t px py pz qx qy qz qw` rows -> PoseSeries, checking that quaternions are unit
    (`line_of` as for check_increasing)."""
    q = table[:, 4:8]
    with np.errstate(over="ignore"):  # a component of 1e300: its norm is inf, refused below
        norms = np.linalg.norm(q, axis=1)
    off = ~(np.abs(norms - 1.0) <= 1e-2)
    if off.any():
        i = int(np.argmax(off))
        raise DataError(where, f"quaternion norm {norms[i]:.3f} is not 1", line_of(i))
    # Normalise only what is not unit already, so that re-reading written poses is exact.
    q = np.where(np.abs(norms - 1.0)[:, None] > 1e-12, q / norms[:, None], q)
    return PoseSeries(t=table[:, 0], p_w_c=table[:, 1:4], q_w_c=q)


def calibration_problem(values: list[float], width: int, height: int) -> str | None:
    """What makes `fx fy cx cy [k1 k2 p1 p2 [k3]]` impossible for a width x height pinhole camera
    with radial-tangential distortion, or None: focal lengths between 0.1 and 100 sensor widths
    (fields of view of about 160 down to 0.6 degrees), the principal point on the sensor,
    |k1|, |k2|, |k3| <= 10 and |p1|, |p2| <= 1 (beyond, the model no longer maps the sensor)."""
    fx, fy, cx, cy = values[:4]
    side = max(width, height)
    if not (0.1 * side <= fx <= 100 * side and 0.1 * side <= fy <= 100 * side):
        return f"focal lengths fx = {fx:g}, fy = {fy:g} px are not those of a {width}x{height} camera " \
               f"({0.1 * side:g} to {100 * side:g} px)"
    if not (0 <= cx <= width and 0 <= cy <= height):
        return f"principal point cx = {cx:g}, cy = {cy:g} px lies off the {width}x{height} sensor"
    dist = (values[4:] + [0.0] * 5)[:5]
    if max(abs(dist[0]), abs(dist[1]), abs(dist[4])) > 10 or max(abs(dist[2]), abs(dist[3])) > 1:
        return f"distortion k1 k2 p1 p2 k3 = {' '.join(f'{d:g}' for d in dist)} out of range (|k| <= 10, |p| <= 1)"
    return None
