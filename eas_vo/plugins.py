"""The plugin contracts: what a dataset, a frontend, a tracker and a backend provide.

Every plugin class has three class attributes:

    name: str            the name users type (`--frontend NAME`); equal to its entry-point name
    description: str     one line, shown by `eas-vo list`
    Config: type         a frozen dataclass; its fields are the plugin's config keys (defaults
                         required); an optional `validate()` method raises ConfigError

and is registered under the entry-point group `eas_vo.datasets`, `eas_vo.frontends`,
`eas_vo.trackers` or `eas_vo.backends`. The pipeline calls only what is declared
here; members marked optional have the default given. Signatures that may grow take
keyword arguments after `*`.

Data flow: Dataset --Sample--> Frontend --uint8 image--> Tracker --FrameRecord, edges-->
Backend --R_w_c per frame--> evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, ClassVar, Iterator, Sequence

import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.errors import EasVoError
from eas_vo.types import FrameRecord, ImuSeries, PoseSeries, RelativeRotation, Sample, search_times


@dataclass(frozen=True)
class NoConfig:
    """A plugin without options."""


class Dataset:
    """A recording: frames and events in time order, the camera, optional ground truth and IMU.

    Required: `__init__(location, config)` setting `camera` (and `ground_truth`, `imu`
    when the recording has them); `frame_times()`, `load_frame(k)`, `events()`.
    Optional (defaults here): `can_open`, `label`, `no_frames_reason`, `no_camera_reason`, `clock_origin_ns`,
    `sensor_size`, `contents`, `data_warnings`, `window`, `samples`; `catalogue` and `fetch` for a plugin whose recordings can be
    downloaded by name (`eas-vo fetch`, `--dataset PLUGIN:NAME`).
    """

    name: ClassVar[str] = "dataset"
    description: ClassVar[str] = ""
    Config: ClassVar[type] = NoConfig

    #: Intrinsics, distortion and sensor size; None when the recording holds no calibration and
    #: none was given (`registry.open_dataset` then refuses it for anything but a description).
    camera: CameraModel | None
    #: Camera-to-world poses, or None.
    ground_truth: PoseSeries | None = None
    #: Gyro and accelerometer readings (IMU frame), or None.
    imu: ImuSeries | None = None
    #: What the user opened, for messages and plots (e.g. the folder path).
    label: str = ""
    #: Why `load_frame` returns None, for the error a frame-based frontend gives.
    no_frames_reason: str = "the dataset has no APS frames"
    #: Why `camera` is None, and what to give instead (one line naming the file).
    no_camera_reason: str = "the dataset has no calibration"
    #: The recording's clock at t = 0 [ns]: every time the dataset gives (frames, events, IMU,
    #: ground truth) is relative to it, and output files add it back. 0 for clocks that start
    #: near zero; a reader of a Unix-time clock sets it (datasets.recording.clock_origin_ns),
    #: since float64 seconds at 1.7e9 keep only about 0.24 us.
    clock_origin_ns: int = 0

    @property
    def sensor_size(self) -> tuple[int, int] | None:
        """(width, height) [px] of the sensor; default: the camera's (None without one)."""
        return (self.camera.width, self.camera.height) if self.camera is not None else None

    def contents(self) -> list[str]:
        """What the file holds in its own terms (topics or streams with their types, counts,
        encodings), one line each, for `eas-vo info`. Default: none."""
        return []

    def __init__(self, location: str, config=None):
        """Open `location` (the part of `--dataset` after `NAME:`, or the whole of it)."""
        raise NotImplementedError

    @classmethod
    def can_open(cls, location: str) -> bool:
        """Whether this plugin recognises `location` (a path, a name) without `NAME:` in front.

        Must be cheap and never raise (like xarray's `guess_can_open`); the registry asks
        every dataset plugin and needs exactly one yes. Default: no (explicit form only).
        """
        return False

    @classmethod
    def catalogue(cls) -> dict[str, str]:
        """{name: checksum} of the recordings `fetch` can download. Default: none."""
        return {}

    @classmethod
    def fetch(cls, name: str, folder: str | None = None, progress: bool = False) -> Path:
        """Download recording `name` (one of `catalogue()`) into `folder` (default: the plugin's
        data folder) unless it is already there and verified; return its location."""
        raise EasVoError(f"dataset plugin {cls.name!r} cannot fetch recordings")

    def frame_times(self) -> np.ndarray:
        """(N,) sample timestamps [s], non-decreasing."""
        raise NotImplementedError

    def load_frame(self, k: int) -> np.ndarray | None:
        """Grayscale uint8 APS frame k (H, W), or None for an event-only stream."""
        raise NotImplementedError

    def events(self) -> np.ndarray:
        """The whole event stream as EVENT_DTYPE (possibly memory-mapped), sorted by time."""
        raise NotImplementedError

    def data_warnings(self) -> list[str]:
        """One line per kind of problem tolerated while reading (`--lenient`). Default: none."""
        return []

    def window(self, start_s: float = 0.0, duration_s: float = np.inf) -> np.ndarray:
        """Indices of the frames in [t0 + start_s, t0 + start_s + duration_s), t0 the first frame time."""
        times = self.frame_times()
        if len(times) == 0:
            return np.arange(0)
        with np.errstate(over="ignore"):  # --start 1e308 --duration 1e308: an empty window, not a warning
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
    """Turns a Sample into one grayscale uint8 image of sensor size (height, width).

    Required: `__call__(sample)`. Optional: `needs_frames` (default False: the frontend
    reads only events), `needs_events` (default False), `shows_the_past` (default False),
    `makes_images` (default True), `reset()` (default: nothing to forget). Stateful frontends
    consume `sample.events_since_previous` incrementally.
    """

    name: ClassVar[str] = "frontend"
    description: ClassVar[str] = ""
    Config: ClassVar[type] = NoConfig
    #: True if `__call__` reads `sample.frame` (the run refuses event-only datasets).
    needs_frames: ClassVar[bool] = False
    #: True if `__call__` reads events (the run warns when there are none, or when they end
    #: before the window's last frames).
    needs_events: ClassVar[bool] = False
    #: True if the image remembers events from before the frame's time (a time surface): it
    #: shows the scene some ms in the past, so a clock shift the run's IMU check finds is taken
    #: for the image's lag, not the IMU's clock (no run.imu_time_offset_s is suggested, and
    #: run.imu_time_offset_auto keeps the configured clock).
    shows_the_past: ClassVar[bool] = False
    #: False for the `no_image` frontend only: it makes no image, the pipeline never calls it and
    #: the tracker gets `image=None` (for trackers that read no images: Tracker.reads_images).
    makes_images: ClassVar[bool] = True

    def __init__(self, config=None, camera: CameraModel | None = None):
        self.config = config if config is not None else self.Config()
        self.camera = camera

    def reset(self) -> None:
        """Forget any state accumulated from earlier samples."""

    def __call__(self, sample: Sample) -> np.ndarray:
        """The image of `sample`: uint8, (camera.height, camera.width)."""
        raise NotImplementedError


class Tracker:
    """Measures relative rotations between the images of one sequence, fed in time order.

    Required: `process(image, t)`. Optional: `reset()`, which `__init__` calls last, so a
    tracker sets up its per-sequence state there, `submit` (overlap with the next image),
    `needs_imu`, `uses_imu`, `imu_use`, `closes_loops`, `tracker_warnings`, `tracked_points`,
    `needs_events` (default False) and `reads_images` (default True). It never knows which
    frontend made the images. Frame indices count the images given since construction (or reset), from 0.
    """

    name: ClassVar[str] = "tracker"
    description: ClassVar[str] = ""
    Config: ClassVar[type] = NoConfig
    #: True if `process` reads events: it is then called with `sample=` (the dataset's Sample,
    #: as frontends get it: `sample.events_since_previous` are the events since the previous
    #: sample; `sample.events[:sample.event_index]` reaches further back, for a longer window).
    #: The run warns when there are no events, or when they end before the window's last frames.
    needs_events: ClassVar[bool] = False
    #: False if `process` ignores its image (it works from events alone): the run then uses the
    #: `no_image` frontend whatever run.frontend says (no image is made; `image` is None), so an
    #: event-only dataset needs no frontend choice.
    reads_images: ClassVar[bool] = True
    #: One line per way the tracking fell short that no frame's status says (a fallback turned
    #: off for the rest of the run), which the run prints as warnings once it has tracked.
    #: Empty by default.
    tracker_warnings: tuple[str, ...] = ()
    #: What the tracker reads the gyro for when `uses_imu`, for the run's summary ("gyro used by
    #: the NAME tracker as ..."): the built-ins start their search from it (klt: where the
    #: features move; cmax: each window's first rotation) and measure the rotation themselves.
    imu_use: ClassVar[str] = "the start of its search for each rotation"

    def __init__(self, config=None, camera: CameraModel | None = None, *, imu: ImuSeries | None = None):
        """`camera`: the images' intrinsics and distortion; `imu`: the dataset's, when it has one,
        in the camera frame on the frames' clock (ImuSeries.in_camera_frame)."""
        self.config = config if config is not None else self.Config()
        self.camera = camera
        self.imu = imu
        self.reset()

    def reset(self) -> None:
        """Forget every image seen (called by `__init__`)."""

    @property
    def needs_imu(self) -> bool:
        """Whether this configuration cannot work without the dataset's IMU: the pipeline then
        refuses a dataset that has none, before any work (default: False)."""
        return False

    @property
    def uses_imu(self) -> bool:
        """Whether this configuration reads the IMU when the dataset has one (the pipeline then
        checks it before any work, and tracks again without it when the images contradict it;
        default: False)."""
        return False

    @property
    def closes_loops(self) -> bool:
        """Whether this configuration looks for loops: the run then counts the edges it marked
        `loop` and says how many closed, none included (default: False; the count is then null,
        though rotation.png still marks any edge marked `loop`)."""
        return False

    def process(
        self, image: np.ndarray | None, t: float, *, sample: Sample | None = None
    ) -> tuple[FrameRecord, list[RelativeRotation]]:
        """Take the next image (uint8, sensor size; None when `reads_images` is False) taken at
        `t` [s], and (only when `needs_events`) its `sample`.

        Returns the frame's record (its `index` is this image's frame index) and the
        relative rotations measured now, each `R_i_j` with j this frame and i < j, with
        `loop=True` on those that close a loop.
        """
        raise NotImplementedError

    def submit(
        self, image: np.ndarray | None, t: float, **kwargs
    ) -> Callable[[], tuple[FrameRecord, list[RelativeRotation]]]:
        """Start on the next image (as `process`); returns a function that gives `process`'s
        result for it. The run may submit the next image before it takes this result, and takes
        results in order. By default the image is processed at once; a tracker overrides this to
        leave part of its work to another thread while the next image is tracked, with results
        identical to `process`'s (the run calls `process` with `--threads 1`)."""
        result = self.process(image, t, **kwargs)
        return lambda: result

    def tracked_points(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The points behind the frame last given to `process`, for a viewer (`eas-vo view`
        replays the tracking to draw them; a run reads none): their positions in its image
        (N, 2) [px] and which of them its rotation's model counts as inliers (N,) bool. None (the
        default), at any time, for a tracker that tracks no points."""
        return None


@dataclass(frozen=True)
class BackendResult:
    """What `Backend.solve` returns: everything one solve found, nothing kept on the backend.

    Attributes:
        R_w_c: (n_frames, 3, 3) camera-to-world rotations, frame 0 at the identity.
        causal_R_w_c: (n_frames, 3, 3) each frame's rotation as an online backend estimated it
            when that frame arrived (written as trajectory_causal.tum); None for a batch solve.
        warnings: one line per way the solution falls short (a solver that failed or did not
            converge, measurements it left out), which the run prints as warnings.
        covariance: (n_frames, 3, 3) the covariance [rad^2] of each R_w_c: of its right
            perturbation in the camera frame, R_w_c,true = R_w_c Exp(delta), delta ~ N(0,
            covariance) (RelativeRotation.covariance's convention, GTSAM's); frame 0's about 0 (it
            defines the world). Written per axis to orientation_sigma.csv and drawn as a band in
            rotation.png; None when the backend does not estimate it (the run then draws the
            chain's, eas_vo.geometry.uncertainty.chain_covariance).
    """

    R_w_c: np.ndarray
    causal_R_w_c: np.ndarray | None = None
    warnings: tuple[str, ...] = ()
    covariance: np.ndarray | None = None


class Backend:
    """Turns relative rotations into absolute camera-to-world rotations, one per frame.

    Required: `solve(n_frames, edges, *, times, imu)` returning a `BackendResult`. Optional:
    `needs_imu`, `uses_imu`, `imu_use`. A backend keeps nothing of one solve for the next.
    """

    name: ClassVar[str] = "backend"
    description: ClassVar[str] = ""
    Config: ClassVar[type] = NoConfig

    #: What the backend reads the gyro for when `uses_imu`, for the run's summary ("gyro used
    #: ... by the NAME backend as ...").
    imu_use: ClassVar[str] = "measurements fused with the tracker's rotations"

    def __init__(self, config=None):
        self.config = config if config is not None else self.Config()

    @property
    def needs_imu(self) -> bool:
        """Whether this configuration cannot work without the dataset's IMU: the pipeline then
        refuses a dataset that has none, before any work (default: False)."""
        return False

    @property
    def uses_imu(self) -> bool:
        """Whether this configuration reads the IMU when the dataset has one (the pipeline then
        may re-time it for the backend: run.imu_time_offset_auto; default: False)."""
        return False

    def solve(
        self,
        n_frames: int,
        edges: Sequence[RelativeRotation],
        *,
        times: np.ndarray | None = None,
        imu: ImuSeries | None = None,
    ) -> BackendResult:
        """The rotations of `n_frames` frames (BackendResult) from the edges and, where the
        backend uses them, the frame times [s] (the pipeline always gives them) and the
        dataset's IMU in the camera frame on the frames' clock (None when it has none)."""
        raise NotImplementedError
