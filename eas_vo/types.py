"""Core data types shared by datasets, frontends, the tracker and backends.

Conventions: time in float64 seconds; `R_a_b` maps vectors in frame b into
frame a; trajectories are camera-to-world (`R_w_c`).
"""

from __future__ import annotations

import functools

from dataclasses import dataclass, field

import cv2
import numpy as np

#: Events as a packed structured array (13 bytes/event): time [s], pixel, polarity.
EVENT_DTYPE = np.dtype([("t", "<f8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])


def empty_events() -> np.ndarray:
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


#: Lens models and the names of their distortion coefficients, in order: `radtan`, OpenCV's
#: radial-tangential (the ECD calib.txt order, ROS's plumb_bob) and `equidistant`, the
#: Kannala-Brandt fisheye model of OpenCV's cv2.fisheye, kalibr and ROS (ORB-SLAM3's
#: KannalaBrandt8). docs/camera_models.md has their equations.
LENS_MODELS = {"radtan": ("k1", "k2", "p1", "p2", "k3"), "equidistant": ("k1", "k2", "k3", "k4")}


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with a lens model (LENS_MODELS): it alone projects, undistorts and makes
    undistortion maps, so a new lens model is a change here only.

    Attributes:
        width, height: sensor size [px].
        K: 3x3 intrinsic matrix [px].
        dist: distortion coefficients in the order of `model` (LENS_MODELS).
        model: `radtan` (default) or `equidistant`.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    model: str = "radtan"

    def __post_init__(self):
        if self.model not in LENS_MODELS:
            raise ValueError(f"unknown lens model {self.model!r}: one of {', '.join(LENS_MODELS)}")
        if len(self.dist) != len(LENS_MODELS[self.model]):
            raise ValueError(f"the {self.model} lens model takes {len(LENS_MODELS[self.model])} distortion coefficients, not {len(self.dist)}")

    @classmethod
    def from_calib(cls, values, width: int = 240, height: int = 180) -> "CameraModel":
        """Build from the ECD `calib.txt` values `fx fy cx cy k1 k2 p1 p2 k3`."""
        fx, fy, cx, cy, *dist = [float(v) for v in values]
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        return cls(width, height, K, np.array((dist + [0.0] * 5)[:5]))

    @property
    def focal_px(self) -> float:
        return float(0.5 * (self.K[0, 0] + self.K[1, 1]))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Normalised image coordinates (N, 2) or rays in the camera frame (N, 3) -> distorted
        pixel coordinates (N, 2) [px]. Rays need z > 0 for `radtan`; `equidistant` maps every
        direction (it distorts the angle to the optical axis, not its tangent; the backward axis
        lands on the principal point)."""
        from eas_vo.geometry.lens import project_points

        p = np.asarray(points, dtype=np.float64)
        p = np.ascontiguousarray(p.reshape(-1, p.shape[-1]))
        out = np.empty((len(p), 2))
        project_points(p, np.asarray(self.K, np.float64), np.asarray(self.dist, np.float64), self.model == "equidistant", out)
        return out

    @property
    def distorted(self) -> bool:
        """Whether rays do not project as through a pinhole: any `radtan` coefficient not zero, or
        the `equidistant` model (a fisheye even with its coefficients all zero)."""
        return self.model != "radtan" or bool(np.any(np.asarray(self.dist) != 0))

    @functools.cached_property
    def pixel_rays(self) -> np.ndarray:
        """(height * width, 3) rays (z = 1) of the sensor's pixels, row by row (undistorted once)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        rays = self._rays(np.column_stack([u.ravel(), v.ravel()]))
        rays.flags.writeable = False  # shared by every use of this camera
        return rays

    def rotated_pixels(self, R_to_from: np.ndarray, pts_px: np.ndarray) -> np.ndarray:
        """Where pixels pts_px (N, 2) [px] of a view lie in a view rotated from it (ray_to =
        R_to_from @ ray_from), through the lens model both ways: (N, 2) [px]; -1 for rays
        behind a `radtan` camera."""
        return self._rays_to_pixels(self._rays(pts_px) @ np.asarray(R_to_from, np.float64).T)

    def rotation_maps(self, R_from_to: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (x, y), each (height, width) float32 [px]: for every pixel of a view
        rotated from another (ray_from = R_from_to @ ray_to), where it lies in that other view's
        image, through the lens model; -1 for rays behind a `radtan` camera (cv2.remap's border).
        A lens model that folds back beyond its calibrated field of view maps what it gives there."""
        px = self._rays_to_pixels(self.pixel_rays @ np.asarray(R_from_to, np.float64).T).astype(np.float32)
        return px[:, 0].reshape(self.height, self.width), px[:, 1].reshape(self.height, self.width)

    def _rays(self, pts_px: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) [px] -> their rays (N, 3) in the camera frame, z = 1."""
        rays = np.ones((len(pts_px), 3))
        rays[:, :2] = self.undistort(pts_px)
        return rays

    def _rays_to_pixels(self, rays: np.ndarray) -> np.ndarray:
        """project(rays), -1 for rays `radtan` cannot project (z <= 0: behind the camera)."""
        px = self.project(rays)
        if self.model == "radtan":
            px[rays[:, 2] <= 0] = -1.0
        return px

    def undistort(self, pts_px: np.ndarray) -> np.ndarray:
        """Distorted pixel coordinates (N, 2) [px] -> normalised image coordinates (N, 2)."""
        pts = np.ascontiguousarray(pts_px, dtype=np.float64).reshape(-1, 1, 2)
        if len(pts) == 0:
            return np.empty((0, 2))
        if self.model == "equidistant":
            return cv2.fisheye.undistortPoints(pts, self.K, self.dist).reshape(-1, 2)
        return cv2.undistortPoints(pts, self.K, self.dist).reshape(-1, 2)

    def undistort_maps(self, K_new: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (x, y), each (height, width) float32 [px]: for every pixel of the
        undistorted pinhole view with intrinsics K_new (default K), where it lies in this
        camera's image."""
        K_new = self.K if K_new is None else np.asarray(K_new, dtype=np.float64)
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ np.linalg.inv(K_new).T
        px = self.project(rays).astype(np.float32)
        return px[:, 0].reshape(u.shape), px[:, 1].reshape(u.shape)

    def fold(self) -> tuple[float, float, float] | None:
        """Where the lens' radial projection stops growing inside the sensor, or None when it
        grows out to the sensor's farthest corner (the pixel edges, (0, 0) to (width, height)):
        (its radius from the principal point [px, focal_px], the ray's angle to the optical axis
        there [rad], the farthest corner's radius [px]). Beyond such a fold two rays land on one
        pixel and undistortion inverts the wrong branch. `equidistant` maps rays up to 180 deg: a
        sensor reaching past that radius folds there. The tangential terms of `radtan` (p1 p2)
        are left out: the radial part decides whether the projection folds."""
        from eas_vo.geometry.lens import first_fold

        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        corner = max(np.hypot((u - cx) / fx, (v - cy) / fy) for u in (0, self.width) for v in (0, self.height))
        if self.model == "equidistant":
            coefficients, theta = self.dist, lambda x: x
            x = first_fold(coefficients, np.pi)
        else:
            coefficients, theta = (self.dist[0], self.dist[1], self.dist[4]), np.arctan
            x = first_fold(coefficients, np.inf)
        radius = x * (1.0 + sum(c * x ** (2 * n + 2) for n, c in enumerate(coefficients))) if np.isfinite(x) else np.inf
        if radius >= corner:
            return None
        return float(radius * self.focal_px), float(theta(x)), float(corner * self.focal_px)

    def calib_values(self) -> list[float]:
        """`fx fy cx cy` and the distortion coefficients in the order of `model`."""
        K = self.K
        return [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *self.dist]


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
        the next one instead reads the gyro half a sample late (2.5 ms at 200 Hz: on a speed-4
        simulated sequence its rotation between frames was 0.47 deg off the truth, median;
        0.075 deg so). Before the first and after the last reading, held."""
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
        estimated_sigma_rad: the estimator's own 1-sigma uncertainty of R_i_j [rad, per axis]
            (e.g. from the curvature of its objective); 0: it gives none, the backends then
            derive one from the inliers.
    """

    i: int
    j: int
    R_i_j: np.ndarray
    inliers: int = 0
    inlier_ratio: float = 1.0
    residual_rad: float = 0.0
    loop: bool = False
    estimated_sigma_rad: float = 0.0

    @property
    def sigma_rad(self) -> float:
        """A rough 1-sigma uncertainty of R_i_j [rad]: the estimator's own when it gives one,
        else from its quality: the inlier noise over sqrt(inliers), inflated by 1 / inlier_ratio
        (inf without inliers)."""
        if self.estimated_sigma_rad > 0:
            return self.estimated_sigma_rad
        if self.inliers <= 0:
            return float("inf")
        return self.residual_rad / np.sqrt(self.inliers) / max(self.inlier_ratio, 1e-3)


@dataclass(frozen=True)
class FrameRecord:
    """What the tracker did with one frame.

    Attributes:
        index, t: frame index and time [s].
        nc: correspondences tracked from the previous frame (the paper's NC).
        inliers: inliers of the frame-to-frame model (0 when no model was estimated); for an
            event tracker (cmax), the events its estimate rests on.
        status: `first`; `ok`; `weak` (a rotation was measured but its model is weak: too few
            inliers, a low inlier ratio or a large residual, see `reason`); `lost` (nothing was
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
