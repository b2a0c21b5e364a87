"""A run folder as a Rerun recording (`eas-vo view`, `eas-vo run --view`): its run.rrd, written
by io.rerun_log from the folder's files and from a replay of its frames.

The images and tracked points are not among a run's files: the dataset, frontend and tracker are
opened again from the folder's config.toml (open_pipeline) and the run's window is replayed frame
by frame, the tracker (when it has points: Tracker.tracked_points) fed as the run fed it. Status,
orientations, errors and uncertainties come from the run's own files."""

from __future__ import annotations

import csv
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo import config as config_mod
from eas_vo.errors import EasVoError
from eas_vo.evaluation.ape import tum_aligned_rotations
from eas_vo.geometry.rotations import geodesic_angle, matrices_from_quats
from eas_vo.io.outputs import added_file
from eas_vo.io.rerun_log import RerunLog, rerun_sdk
from eas_vo.io.tum import read_tum
from eas_vo.pipeline.parts import open_pipeline
from eas_vo.types import search_times

#: The recording's name in the run folder.
RECORDING = "run.rrd"
#: The files a run folder must hold to be viewed (groundtruth.tum, orientation_sigma.csv are optional).
NEEDED = ("config.toml", "frames.csv", "trajectory.tum")
#: At most this many events of the window around the middle frame are shown (evenly thinned).
MAX_EVENTS = 50_000


@dataclass(frozen=True)
class Frames:
    """frames.csv's columns the recording shows, one entry a frame."""

    t_s: np.ndarray  # (N,) time [s], as the run's files write it
    nc: np.ndarray  # (N,) correspondences
    inliers: np.ndarray  # (N,)
    status: list[str]
    reason: list[str]

    @property
    def index(self) -> np.ndarray:
        return np.arange(len(self.t_s))


@dataclass(frozen=True)
class Recording:
    """What write_recording wrote: the file, the frames in it, and at how many frames the
    replayed tracker tracked another number of correspondences than frames.csv says."""

    path: Path
    frames: int
    replay_differs: int


def write_recording(run: str | Path) -> Recording:
    """Write RUN/run.rrd, the Rerun recording of the run folder `run` (io.rerun_log's entities),
    replacing an earlier one; a one-line error for a folder that is not a run, or without rerun-sdk."""
    folder = _run_folder(run)
    rerun_sdk()  # before any work
    frames = _read_frames(folder / "frames.csv")
    config = config_mod.resolve(str(folder / "config.toml"), {}, [])
    with added_file(folder, RECORDING) as tmp:
        log = RerunLog(tmp, folder.name)
        try:
            differs = _replay(config, frames, log)
            _log_files(folder, frames, log)
        finally:
            log.close()
    return Recording(folder / RECORDING, len(frames.t_s), differs)


def _run_folder(run: str | Path) -> Path:
    """`run` resolved, if it is a folder holding a run's NEEDED files; else a one-line error."""
    folder = Path(run).expanduser().resolve()
    if not folder.is_dir():
        raise EasVoError(f"{run} is not a folder; give the folder of a run (eas-vo run --out)")
    missing = [name for name in NEEDED if not (folder / name).is_file()]
    if missing:
        raise EasVoError(f"{run} is not a run folder: it holds no {' or '.join(missing)} (eas-vo run writes them)")
    return folder


def _read_csv(path: Path, parse):
    """`parse(rows)` of the CSV file `path` (a dict a row); a one-line error naming the file when
    it holds no row or its columns do not read as eas-vo wrote them."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    try:
        if rows:
            return parse(rows)
    except (KeyError, TypeError, ValueError):
        pass
    raise EasVoError(f"{path}: holds no frame, or not as eas-vo writes it (docs/outputs.md)")


def _read_frames(path: Path) -> Frames:
    """frames.csv (pipeline.tracking.FrameLog's) -> Frames."""
    return _read_csv(
        path,
        lambda rows: Frames(
            np.array([float(r["t"]) for r in rows]),
            np.array([int(r["nc"]) for r in rows]),
            np.array([int(r["inliers"]) for r in rows]),
            [r["status"] for r in rows],
            [r["reason"] for r in rows],
        ),
    )


def _replay(config: config_mod.ResolvedConfig, frames: Frames, log: RerunLog) -> int:
    """Each frame's image and tracked points, from the run's window replayed; the events after the
    middle frame, up to one median frame interval, as a point cloud. Returns at how many frames the
    replay's correspondences differ from frames.csv's."""
    parts = open_pipeline(config)
    rc, n = config.run, len(frames.t_s)
    tracker = parts.tracker if parts.tracker.tracked_points() is not None else None
    middle, differs = n // 2, 0
    for k, sample in enumerate(itertools.islice(parts.dataset.samples(rc.start_s, rc.duration_s), n)):
        image = parts.frontend(sample) if parts.frontend.makes_images else None
        points = None
        if tracker is not None:
            record, _ = tracker.process(image, sample.t, **({"sample": sample} if tracker.needs_events else {}))
            differs += int(record.nc != frames.nc[k])
            points = tracker.tracked_points()
        log.frame(k, float(frames.t_s[k]), image, points)
        if k == middle:
            interval_s = float(np.median(np.diff(frames.t_s))) if n > 1 else 0.0
            _log_events(log, sample.events, sample.t, interval_s, parts.dataset.camera.width)
    return differs


def _log_events(log: RerunLog, events: np.ndarray, t0_s: float, interval_s: float, width_px: int) -> None:
    """The events of [t0_s, t0_s + interval_s) [s], at most MAX_EVENTS of them (every k-th)."""
    if interval_s <= 0:
        return
    start, end = search_times(events, [t0_s, t0_s + interval_s])
    window = events[start:end]
    if len(window):
        log.events(np.asarray(window[:: math.ceil(len(window) / MAX_EVENTS)]), t0_s, t0_s + interval_s, width_px)


def _log_files(folder: Path, frames: Frames, log: RerunLog) -> None:
    """Status and counts (frames.csv), the estimate (trajectory.tum, aligned to the ground truth
    at its first frame as the APE is), the truth and the error (groundtruth.tum) and the error
    the covariance predicts (orientation_sigma.csv)."""
    k, t = frames.index, frames.t_s
    log.statuses(k, t, frames.status, frames.reason)
    log.series("tracking/nc", k, t, frames.nc)
    log.series("tracking/inliers", k, t, frames.inliers)
    estimate = read_tum(folder / "trajectory.tum", ordered=False)
    if len(estimate.t) != len(t):
        raise EasVoError(f"{folder}: trajectory.tum holds {len(estimate.t)} poses and frames.csv {len(t)} frames")
    R_est = matrices_from_quats(estimate.q_w_c)
    aligned = tum_aligned_rotations(folder / "trajectory.tum", folder / "groundtruth.tum")
    if aligned is not None:
        t_gt, R_gt, R_aligned = aligned
        scored = np.searchsorted(estimate.t, t_gt)  # the frames the ground truth scores
        R_est = R_aligned[0] @ R_est[scored[0]].T @ R_est  # every frame, aligned as the scored ones
        log.orientations("truth", scored, t[scored], R_gt)
        log.series("error/ape_deg", scored, t[scored], np.degrees(geodesic_angle(R_gt, R_aligned)))
    log.orientations("estimate", k, t, R_est)
    predicted = _predicted_error_deg(folder / "orientation_sigma.csv")
    if predicted is not None:
        log.series("error/predicted_deg", *predicted)


def _predicted_error_deg(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(frames, t [s], RMS error [deg]) the backend's covariance predicts (the square root of its
    trace, as rotation.png draws it), the chain's where the backend gives none; None without the file."""
    if not path.is_file():
        return None

    def parse(rows):
        axes = [f"backend_sigma_{a}_deg" for a in "xyz"]
        if not rows[0][axes[0]]:
            axes = [f"chain_sigma_{a}_deg" for a in "xyz"]
        sigmas = np.array([[float(r[axis]) for axis in axes] for r in rows])
        frames = np.array([int(r["index"]) for r in rows])
        return frames, np.array([float(r["t"]) for r in rows]), np.sqrt(np.sum(sigmas**2, axis=1))

    return _read_csv(path, parse)
