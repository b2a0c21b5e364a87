"""The per-frame loop (frontend, tracker) and frames.csv, one row a frame written as it goes."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from dataclasses import replace as with_changes
from pathlib import Path

import numpy as np

from eas_vo import concurrency
from eas_vo.config import ResolvedConfig
from eas_vo.errors import EasVoError
from eas_vo.geometry.uncertainty import consecutive_steps
from eas_vo.io.tables import clock_time
from eas_vo.orb import OrbStats
from eas_vo.pipeline.parts import Pipeline, check_frame
from eas_vo.types import FrameRecord, RelativeRotation

#: frames.csv's columns and their types in memory (frame_table; "U": text as wide as the longest).
FRAMES_COLUMNS = (
    ("index", "i8"),
    ("t", "f8"),
    ("nc", "i8"),
    ("inliers", "i8"),
    ("status", "U"),
    ("redetected", "?"),
    ("inlier_ratio", "f8"),
    ("residual_px", "f8"),
    ("reason", "U"),
    ("events", "i8"),
    ("contrast_gain", "f8"),
    ("sigma_deg", "f8"),
    ("sigma_x_deg", "f8"),
    ("sigma_y_deg", "f8"),
    ("sigma_z_deg", "f8"),
)
FRAMES_CSV_FIELDS = tuple(name for name, _ in FRAMES_COLUMNS)


@dataclass
class Tracked:
    """What tracking produced: a record per frame, the measured edges, and whether it was cut short."""

    records: list[FrameRecord] = field(default_factory=list)
    edges: list[RelativeRotation] = field(default_factory=list)
    orb: OrbStats | None = None  # ORB statistics of the images (run.orb_stats)
    closes_loops: bool = False  # the tracker looked for loops (Tracker.closes_loops)
    interrupted: KeyboardInterrupt | None = None

    @property
    def times(self) -> np.ndarray:
        return np.array([r.t for r in self.records])


def track(parts: Pipeline, config: ResolvedConfig, frames_csv: Path | None = None, progress: bool = False) -> Tracked:
    """The per-frame loop: frontend, tracker, and the frame's row in frames.csv (written as it goes).

    An interrupt stops the loop and is kept in the result; with fewer than 2 frames it is re-raised.
    """
    rc = config.run
    tracked = Tracked(orb=OrbStats() if rc.orb_stats else None, closes_loops=parts.tracker.closes_loops)
    n_window = len(parts.dataset.window(rc.start_s, rc.duration_s))
    overlap = concurrency.threads() > 1  # the tracker may finish a frame while the next is tracked
    pending = None  # the submitted frame whose result is not taken yet
    previous_image, repeated = None, set()  # the tracker's positions of images equal to the one before

    def take(record: FrameRecord, edges: list) -> None:
        if record.index != len(tracked.records):  # an interrupt lost the frame before it
            return
        if record.index in repeated and record.status in ("ok", "weak"):
            # No camera's noise repeats to the bit: a driver sent the frame again, or the frontend
            # made nothing new (no events). Its identity measures nothing, stillness least of all.
            record, edges = (
                with_changes(record, status="lost", inliers=0, reason="the same image as the previous frame"),
                [],
            )
        tracked.records.append(record)
        tracked.edges.extend(edges)
        log.write(record, consecutive_steps(edges).get(record.index))
        bar.update(1)
        if record.index % 10 == 0:
            bar.set_postfix(nc=record.nc, refresh=False)

    with FrameLog(frames_csv, parts.dataset.clock_origin_ns) as log, _progress(n_window, progress, rc) as bar:
        try:
            for position, sample in enumerate(
                concurrency.ahead(parts.dataset.samples(rc.start_s, rc.duration_s))
            ):  # the next one read meanwhile
                check_frame(sample.frame, parts.dataset, sample.index, sample.t)
                image = None
                if parts.frontend.makes_images:
                    image = parts.frontend(sample)
                    check_image(image, parts.dataset.camera, rc.frontend, sample)
                    if previous_image is not None and np.array_equal(image, previous_image):
                        repeated.add(position)  # the tracker's index of this image
                    previous_image = image
                    if tracked.orb is not None:
                        tracked.orb.add(image)
                events = {"sample": sample} if parts.tracker.needs_events else {}
                if not overlap:
                    take(*parts.tracker.process(image, sample.t, **events))
                    continue
                submitted = parts.tracker.submit(image, sample.t, **events)
                if pending is not None:
                    take(*pending())
                pending = submitted
            if pending is not None:
                take(*pending())
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: keep what was processed
            if pending is not None:
                take(*pending())  # a frame already tracked (unless taken or cut off): its measurement is a moment away
            tracked.interrupted = exc
    if len(tracked.records) < 2:
        if tracked.interrupted is not None:
            raise tracked.interrupted
        raise EasVoError(f"{parts.dataset.label}: fewer than 2 samples were processed")
    return tracked


def check_image(image, camera, frontend: str, sample) -> None:
    """A frontend's output must be a uint8 image of sensor size (H, W): else one error line."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.shape != (camera.height, camera.width):
        got = f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        raise EasVoError(
            f"frontend {frontend!r} returned {got} for frame {sample.index} (t={sample.t:.6f} s); "
            f"expected uint8 ({camera.height}, {camera.width})"
        )


class FrameLog:
    """frames.csv, one row per frame, flushed as it goes so an interrupted run keeps its rows:
    the frame's record and the uncertainty of its consecutive step (the edge from the frame
    before: the square root of its covariance's largest eigenvalue and of its diagonal, in
    degrees; empty without one)."""

    def __init__(self, path: Path | None, origin_ns: int = 0):
        self.path = path
        self.origin_ns = origin_ns

    def __enter__(self):
        self._fh = open(self.path, "w", newline="") if self.path else None
        if self._fh:
            self._writer = csv.writer(self._fh, lineterminator="\n")
            self._writer.writerow(FRAMES_CSV_FIELDS)
        return self

    def write(self, r: FrameRecord, step: RelativeRotation | None = None) -> None:
        """The row of record `r` and of `step`, the edge r.index - 1 -> r.index (None: none measured)."""
        if self._fh:
            index, t, nc, inliers, status, redetected, ratio, residual, reason, events, gain, *sigmas = frame_values(
                r, step
            )
            self._writer.writerow(
                [
                    index,
                    clock_time(t, self.origin_ns),
                    nc,
                    inliers,
                    status,
                    int(redetected),
                    f"{ratio:.4f}",
                    f"{residual:.4f}",
                    reason,
                    events,
                    f"{gain:.4f}",
                    *("" if np.isnan(s) else f"{s:.6f}" for s in sigmas),
                ]
            )
            self._fh.flush()

    def __exit__(self, *exc):
        if self._fh:
            self._fh.close()
        return False


def frame_values(r: FrameRecord, step: RelativeRotation | None) -> tuple:
    """The values of frames.csv's row (FRAMES_COLUMNS) of record `r` and its consecutive `step`
    (None: none measured): the time [s] on the run's clock, the step's sigmas [deg] along its worst
    axis and about x, y, z (NaN without a step; inf where its estimator gives no finite
    covariance: no inliers)."""
    sigmas = np.full(4, np.nan)
    if step is not None:
        sigmas = np.degrees([step.sigma_rad, *step.sigmas_rad()])
        sigmas = sigmas if np.all(np.isfinite(sigmas)) else np.full(4, np.inf)
    record = (r.index, r.t, r.nc, r.inliers, r.status, r.redetected, r.inlier_ratio, r.residual_px, r.reason)
    return record + (r.events, r.contrast_gain, *map(float, sigmas))


def frame_table(records: list[FrameRecord], edges: list[RelativeRotation]) -> np.ndarray:
    """frames.csv as a numpy record array, one row a record (columns FRAMES_COLUMNS): times [s]
    on the run's clock (the file adds the recording's clock origin), `redetected` a bool, the
    sigmas [deg] NaN where the file's are empty."""
    steps = consecutive_steps(edges)
    rows = [frame_values(r, steps.get(r.index)) for r in records]
    dtype = [
        (name, f"U{max([1, *(len(row[k]) for row in rows)])}" if kind == "U" else kind)
        for k, (name, kind) in enumerate(FRAMES_COLUMNS)
    ]
    return np.array(rows, dtype=dtype).view(np.recarray)


def _progress(total: int, enabled: bool, rc):
    from tqdm import tqdm

    return tqdm(
        total=total,
        disable=not enabled,
        desc=f"{rc.frontend}+{rc.tracker}+{rc.backend}",
        unit="frame",
        leave=False,
        dynamic_ncols=True,
    )
