"""Data shared by datasets, frontends, trackers and backends (data only: behaviour lives in
the modules that use it; the camera is eas_vo.camera).

Conventions: time in float64 seconds; `R_a_b` maps vectors in frame b into
frame a; trajectories are camera-to-world (`R_w_c`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

#: Events as a packed structured array (13 bytes/event): time [s], pixel, polarity.
EVENT_DTYPE = np.dtype([("t", "<f8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])


def empty_events() -> np.ndarray:
    """No events: an empty array of EVENT_DTYPE."""
    return np.empty(0, dtype=EVENT_DTYPE)


def search_times(events: np.ndarray, times) -> np.ndarray:
    """Index of the first event with `t >= time`, for each time (np.searchsorted, side='left').

    np.searchsorted would first copy the strided `t` field of a whole (memory-mapped)
    stream; this bisection reads about 2 log2(N) values per query, so a window of a
    stream far larger than memory touches only its own pages.
    """
    times = np.atleast_1d(np.asarray(times, dtype=float))
    lo = np.zeros(len(times), np.int64)
    hi = np.full(len(times), len(events), np.int64)
    t = events["t"]
    while True:
        active = lo < hi
        if not active.any():
            return lo
        mid = (lo + hi) // 2
        below = np.zeros(len(times), bool)
        below[active] = t[mid[active]] < times[active]
        lo = np.where(active & below, mid + 1, lo)
        hi = np.where(active & ~below, mid, hi)


@dataclass(frozen=True)
class PoseSeries:
    """Timestamped camera-to-world poses (ground truth).

    Attributes:
        t: (N,) times [s], increasing.
        p_w_c: (N, 3) camera positions in the world [m].
        q_w_c: (N, 4) camera-to-world rotations as quaternions (x, y, z, w).
    """

    t: np.ndarray
    p_w_c: np.ndarray
    q_w_c: np.ndarray


#: A gyro is taken to measure an interval when no stretch of it without a reading is longer
#: than this many median reading intervals (a sample or three lost).
MAX_GAP_READINGS = 4


#: Clock units a timestamp column is often written in by mistake for seconds, as factors of
#: the second (each reader's and the gyro check's unit hint).
TIME_UNITS = {"milliseconds": 1e3, "microseconds": 1e6, "nanoseconds": 1e9}


@dataclass(frozen=True)
class ImuSeries:
    """IMU readings: t [s] (increasing), accelerometer [m/s^2], gyro [rad/s]. A dataset gives
    them in the IMU's frame and clock; trackers and backends get them in the camera frame, on
    the frames' clock (in_camera_frame, applied by the pipeline with the run's camera-IMU
    rotation)."""

    t: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray

    def in_camera_frame(self, R_imu_cam: np.ndarray, time_offset_s: float) -> "ImuSeries":
        """The readings rotated into the camera frame (v_cam = R_imu_cam^T v_imu) and timed on
        the frames' clock (IMU time = frame time + time_offset_s [s])."""
        R = np.asarray(R_imu_cam, float)
        return ImuSeries(self.t - time_offset_s, self.acc @ R, self.gyro @ R)

    def covered(self, t0, t1) -> np.ndarray:
        """Which intervals [t0, t1] [s] (scalars or arrays) the gyro measures: t0 <= t1, and no
        stretch of them without a reading, the ends included, longer than MAX_GAP_READINGS median
        reading intervals (the rates are interpolated across a gap; across a longer one, guessed)."""
        t0, t1 = np.asarray(t0, float), np.asarray(t1, float)
        t = self.t
        if len(t) < 2:
            return np.zeros(np.broadcast(t0, t1).shape, bool)
        limit, wide = self._gaps
        before = np.clip(np.searchsorted(t, t0, side="right") - 1, 0, len(t) - 1)  # the reading at or before t0
        after = np.clip(np.searchsorted(t, t1, side="left"), 0, len(t) - 1)  # the reading at or after t1
        inside = (t0 >= t[0] - limit) & (t1 <= t[-1] + limit)  # beyond the readings by at most one gap
        return (t1 >= t0) & inside & (wide[after] == wide[before])

    @functools.cached_property
    def _gaps(self) -> tuple[float, np.ndarray]:
        """The longest gap `covered` accepts [s] and, per reading, the count of longer ones before it."""
        limit = MAX_GAP_READINGS * float(np.median(np.diff(self.t)))
        return limit, np.concatenate([[0], np.cumsum(np.diff(self.t) > limit)])

    def rates_between(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """[t0, t1] (t0 <= t1) cut at the readings' times: the mean gyro rate over each piece
        (K, 3) [rad/s] and its duration (K,) [s]. Each reading is the rate at its time, linear
        in between (the midpoint rule of VINS-Mono's preintegration): holding a reading until
        the next one instead reads the gyro half a sample late (docs/imu.md, "How readings are
        integrated"). Before the first and after the last reading, held."""
        t = self.t
        first, end = np.searchsorted(t, t0, side="right"), np.searchsorted(t, t1, side="left")
        cuts = np.concatenate([[t0], t[first:end], [t1]])
        middle = 0.5 * (cuts[:-1] + cuts[1:])
        near = slice(max(first - 1, 0), end + 1)  # the readings around [t0, t1]: interpolation needs no others
        return np.stack([np.interp(middle, t[near], self.gyro[near, k]) for k in range(3)], -1), np.diff(cuts)

    def turned_since_start(self):
        """times (any shape) [s] -> the gyro's integrated rate since its first reading (..., 3)
        [rad]: differences of it are the rotation vectors between two times, up to the
        composition of the rotations in between (second order in the angle: under 0.05 deg for
        10 deg between frames). Rates as in rates_between (linear between readings, held
        outside them): a trapezoid sum up to the last reading before each time, and the
        quadratic piece after it. Vectorised, for many pairs at once."""
        T, w = self.t, self.gyro
        dT = np.diff(T)[:, None]
        at_readings = np.vstack([np.zeros(3), np.cumsum(0.5 * (w[:-1] + w[1:]) * dT, axis=0)])
        slope = np.vstack([np.diff(w, axis=0) / dT, np.zeros((1, 3))])  # [rad/s^2]; none after the last

        def turned(times):
            times = np.asarray(times, float)
            k = np.clip(np.searchsorted(T, times, side="right") - 1, 0, len(T) - 1)
            since = (times - T[k])[..., None]  # negative only before the first reading, where it is held
            return at_readings[k] + w[k] * since + 0.5 * slope[k] * np.maximum(since, 0.0) ** 2

        return turned


@dataclass(frozen=True)
class Sample:
    """One step of a dataset: a frame (if any), its time and a view of the events.

    Attributes:
        index: position of the sample in the sequence (0-based).
        t: timestamp [s].
        frame: grayscale uint8 APS frame (H, W), or None for event-only streams.
        events: the whole event stream (a view, never a copy).
        event_index: index of the first event with `t >= self.t`.
        prev_event_index: `event_index` of the previous sample (or of the window start).
    """

    index: int
    t: float
    frame: np.ndarray | None
    events: np.ndarray
    event_index: int
    prev_event_index: int

    @property
    def events_after(self) -> np.ndarray:
        """Events from the sample time on (what EAS aggregates)."""
        return self.events[self.event_index :]

    @property
    def events_since_previous(self) -> np.ndarray:
        """Events between the previous sample and this one (for incremental frontends)."""
        return self.events[self.prev_event_index : self.event_index]


@dataclass(frozen=True)
class RelativeRotation:
    """A measured rotation between frames i and j (j > i): `R_i_j` maps frame-j vectors into frame i.

    Attributes:
        inliers: correspondences the model explains (an event tracker: the events it rests on).
        inlier_ratio: inliers / correspondences offered to the estimator.
        residual_rad: robust per-axis noise of the inliers [rad, ~ px / focal length], from the
            median of their residuals (the angle between rotated and observed bearings for
            the rotation model, the Sampson distance for the essential matrix); 0 when unknown.
        loop: a loop closure (frame i is a keyframe seen again) rather than a measurement of
            the motion since a recent frame.
        covariance: the estimator's own covariance of R_i_j [rad^2] (3, 3): of the right
            perturbation in frame j, R_i_j,true = R_i_j Exp(delta), delta ~ N(0, covariance)
            (GTSAM's convention for a BetweenFactor's noise); None: it gives none, and
            `noise_covariance` derives an isotropic one from the edge's quality.
    """

    i: int
    j: int
    R_i_j: np.ndarray
    inliers: int = 0
    inlier_ratio: float = 1.0
    residual_rad: float = 0.0
    loop: bool = False
    covariance: np.ndarray | None = None

    @property
    def sigma_rad(self) -> float:
        """The largest 1-sigma uncertainty of R_i_j [rad] (along any axis): from the estimator's
        covariance when it gives one, else from its quality: the inlier noise over
        sqrt(inliers), inflated by 1 / inlier_ratio (inf without inliers)."""
        if self.covariance is not None:
            return float(np.sqrt(np.linalg.eigvalsh(self.covariance)[-1]))
        if self.inliers <= 0:
            return float("inf")
        return self.residual_rad / np.sqrt(self.inliers) / max(self.inlier_ratio, 1e-3)

    def noise_covariance(self) -> np.ndarray:
        """The covariance [rad^2] (3, 3) a backend weighs the edge by: the estimator's own, else
        sigma_rad^2 on every axis (inf without inliers)."""
        if self.covariance is not None:
            return self.covariance
        return self.sigma_rad**2 * np.eye(3)

    def sigmas_rad(self) -> np.ndarray:
        """The 1-sigma uncertainty about each of frame j's axes x, y, z [rad] (3,)."""
        return np.sqrt(np.diag(self.noise_covariance()))


@dataclass(frozen=True)
class FrameRecord:
    """What the tracker did with one frame.

    Attributes:
        index, t: frame index and time [s].
        nc: correspondences tracked from the previous frame (the paper's NC).
        inliers: inliers of the frame-to-frame model (0 when no model was estimated); for an
            event tracker (cmax), the events its estimate rests on.
        status: `first`; `ok`; `weak` (a rotation was measured but is less reliable than
            usual: too few inliers, or its covariance predicts an error above the tracker's
            bound, or the motion before it makes it doubtful; see `reason`); `lost` (nothing was
            measured, the previous rotation is kept: too few correspondences or no model);
            `same_time` (the frame has the previous frame's timestamp: frame skipped).
        redetected: features were detected again in this frame (klt: < threshold2).
        inlier_ratio: inliers / the correspondences the frame-to-frame model was fitted to (0
            without one): nc, except where klt's descriptor fallback measured the frame (nc: its
            matches; the model: the LK tracks refined from them, unless that refinement was weak).
        residual_px: per-axis noise of that model's inliers [px] (sigma from their median
            residual; 0 without one); cmax: how far apart the image quadrants' optima lie [px].
        reason: why the frame is `weak` or `lost` ("" otherwise).
        events: events the tracker read for this frame (0 for a tracker of images).
        contrast_gain: an event tracker's contrast at its estimate over the contrast at no
            motion (cmax; 0 when not measured).
    """

    index: int
    t: float
    nc: int
    inliers: int
    status: str
    redetected: bool
    inlier_ratio: float = 0.0
    residual_px: float = 0.0
    reason: str = ""
    events: int = 0
    contrast_gain: float = 0.0
