"""The opened dataset and the plugins built for it (`open_pipeline`), with every check that can
be made before any work: clocks, frame size, the window, the ground truth's overlap, the IMU's readings."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eas_vo import registry
from eas_vo.config import TIME_OFFSET_LIMIT_S, ResolvedConfig
from eas_vo.datasets.calibration import check_frame_size
from eas_vo.datasets.recording import recording_clock_problems, time_source
from eas_vo.errors import EasVoError
from eas_vo.evaluation.ape import MAX_GAP_FRAMES, ground_truth_gap_limit_s, scorable
from eas_vo.geometry.rotations import rotvec_to_matrix
from eas_vo.imu.readings import check_readings
from eas_vo.plugins import Backend, Dataset, Frontend, Tracker
from eas_vo.types import MAX_GAP_READINGS, ImuSeries


@dataclass
class Pipeline:
    """The opened dataset, its IMU in the camera frame (None without one, or when no plugin
    reads it), the plugins built for it and what the IMU's check before any work found."""

    dataset: Dataset
    imu: ImuSeries | None
    frontend: Frontend
    tracker: Tracker
    backend: Backend
    imu_warnings: list[str] = field(default_factory=list)


def open_pipeline(config: ResolvedConfig) -> Pipeline:
    """Open the dataset, check its clocks' units (datasets.recording.recording_clock_problems:
    this reads the event stream once, its first read parsing it into the cache), build the
    plugins and check the window."""
    rc = config.run
    dataset = registry.open_dataset(rc.dataset, config.dataset)
    frontend_cls = registry.get("frontends", rc.frontend)
    first_frame = dataset.load_frame(0)
    if frontend_cls.needs_frames and first_frame is None:
        raise EasVoError(f"frontend {rc.frontend!r} needs APS frames: {dataset.no_frames_reason}")
    clocks = recording_clock_problems(dataset, first_frame is not None)  # before an event-only stream is sampled
    if clocks:
        raise EasVoError(next(iter(clocks.values())))
    if first_frame is not None:  # a frame of another size than the camera's: said before any work
        check_frame(first_frame, dataset, 0, float(dataset.frame_times()[0]))
    if not frontend_cls.makes_images and registry.get("trackers", rc.tracker).reads_images:
        raise EasVoError(
            f"frontend {rc.frontend!r} makes no images and tracker {rc.tracker!r} reads them; choose an image frontend"
        )
    n_window = len(dataset.window(rc.start_s, rc.duration_s))
    if n_window < 2:
        raise EasVoError(
            f"{dataset.label}: the window start={rc.start_s} s, duration={rc.duration_s} s "
            f"holds {n_window} sample(s); at least 2 are needed"
        )
    _check_ground_truth_overlap(dataset, config.run, n_window)
    imu = (
        None
        if dataset.imu is None
        else dataset.imu.in_camera_frame(rotvec_to_matrix(rc.imu_rotvec_cam), rc.imu_time_offset_s)
    )
    parts = Pipeline(
        dataset=dataset,
        imu=imu,
        frontend=frontend_cls(config.frontend, dataset.camera),
        tracker=registry.get("trackers", rc.tracker)(config.tracker, dataset.camera, imu=imu),
        backend=registry.get("backends", rc.backend)(config.backend),
    )
    for kind, plugin in (("tracker", parts.tracker), ("backend", parts.backend)):
        if plugin.needs_imu and dataset.imu is None:
            raise EasVoError(
                f"{kind} {plugin.name!r} as configured needs an IMU and {dataset.label} has none "
                f"(imu.txt, or the bag's IMU topic); change the {kind} settings or the dataset"
            )
    if imu is not None and not (parts.tracker.uses_imu or parts.backend.uses_imu):
        parts.imu = None  # nothing reads it: neither checked nor judged
    if parts.imu is not None:
        window = dataset.frame_times()[dataset.window(rc.start_s, rc.duration_s)]
        parts.imu_warnings = check_readings(parts.imu, window, dataset.label, rc.imu_time_offset_s)
    return parts


def _check_ground_truth_overlap(dataset: Dataset, rc, n_window: int) -> None:
    """A fixed time offset that puts every frame of the window outside the ground truth, or a
    ground truth too sparse to score any of them (evaluation.scorable), would leave nothing to
    evaluate: say so before any work."""
    gt = dataset.ground_truth
    if gt is None or rc.time_offset_auto or len(gt.t) == 0:
        return
    t = dataset.frame_times()[dataset.window(rc.start_s, rc.duration_s)] + rc.time_offset_s
    if scorable(gt.t, t).any():
        return
    where = (
        f"{time_source(dataset, 'ground-truth')}: the ground truth ({len(gt.t)} poses, {gt.t[0]:.3f}-{gt.t[-1]:.3f} s)"
    )
    if np.any((t >= gt.t[0]) & (t <= gt.t[-1])):
        widest = float(np.max(np.diff(gt.t)))
        raise EasVoError(
            f"{where} scores none of the {n_window} frame times of the window ({t[0]:.3f}-{t[-1]:.3f} s): "
            f"its poses lie up to {widest:.3g} s apart, and it is interpolated across gaps of at most "
            f"{ground_truth_gap_limit_s(gt.t, t):.3g} s ({MAX_GAP_READINGS} of its median sample intervals, "
            f"and {MAX_GAP_FRAMES} of the frames' at most)"
        )
    gap_s = float(dataset.frame_times()[0] - gt.t[0])
    hint = (
        "check --time-offset, --start and --duration"
        if abs(gap_s) <= TIME_OFFSET_LIMIT_S
        else f"its clock is not the recording's: put it there with --set dataset.ground_truth_time_offset_s=S "
        f"(S = {gap_s:.6f} would start both together)"
    )
    raise EasVoError(
        f"{where} covers none of the {n_window} frame times of the window ({t[0]:.3f}-{t[-1]:.3f} s with "
        f"the time offset {rc.time_offset_s:+g} s); {hint}"
    )


def check_frame(frame, dataset: Dataset, index: int, t: float) -> None:
    """A dataset's frame `index` (at `t` [s]) must be None or a grayscale uint8 (H, W) image of
    its camera's size: else one error line, before a frontend sees it."""
    if frame is None:
        return
    where = f"{dataset.label}: frame {index} (t={t:.6f} s)"
    if not isinstance(frame, np.ndarray) or frame.ndim != 2 or frame.dtype != np.uint8:
        got = f"{frame.dtype} {frame.shape}" if isinstance(frame, np.ndarray) else type(frame).__name__
        raise EasVoError(f"{where}: the dataset gave {got}; frames are grayscale uint8 (height, width)")
    check_frame_size(dataset.camera, frame.shape[1], frame.shape[0], where, "the frame is")
