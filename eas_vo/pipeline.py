"""One run: dataset -> frontend -> tracker -> backend -> evaluation -> files."""

from __future__ import annotations

import csv
import json
import signal
import threading
import time
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eas_vo import registry
from eas_vo.config import ResolvedConfig, dataset_plugin_name
from eas_vo.errors import EasVoError
from eas_vo.evaluation import RotationErrors, estimate_time_offset, rotation_errors
from eas_vo.geometry import quats_from_matrices
from eas_vo.io import atomic_path, write_text_atomic
from eas_vo.orb import OrbStats
from eas_vo.plugins import Dataset
from eas_vo.tracker import Tracker
from eas_vo.types import FrameRecord, RelativeRotation

FRAMES_CSV_FIELDS = ("index", "t", "nc", "inliers", "status", "redetected")


def open_dataset(spec: str, config=None) -> Dataset:
    """Open `spec`: `synthetic:NAME` (or any `plugin:location`), else an Event Camera Dataset folder."""
    name = dataset_plugin_name(spec)
    cls = registry.get("datasets", name)
    location = spec[len(name) + 1 :] if spec.startswith(f"{name}:") else spec
    return cls(location, config if config is not None else cls.Config())


@dataclass
class RunResult:
    """Everything a run produced, in memory."""

    t: np.ndarray
    R_w_c: np.ndarray
    records: list[FrameRecord]
    edges: list[RelativeRotation]
    errors: RotationErrors | None
    metrics: dict = field(default_factory=dict)
    causal_R_w_c: np.ndarray | None = None  # an online backend's estimate of each frame when it arrived


def run(config: ResolvedConfig, out_dir: str | Path | None = None, progress: bool = False) -> RunResult:
    """Run the configured pipeline; with `out_dir`, write every output file there."""
    started = time.perf_counter()
    rc = config.run
    dataset = open_dataset(rc.dataset, config.dataset)
    frontend_cls = registry.get("frontends", rc.frontend)
    frontend = frontend_cls(config.frontend, dataset.camera)
    backend = registry.get("backends", rc.backend)(config.backend)
    tracker = Tracker(config.tracker, dataset.camera)

    if frontend_cls.needs_frames and dataset.load_frame(0) is None:
        raise EasVoError(f"frontend {rc.frontend!r} needs APS frames: {dataset.no_frames_reason}")
    n_total = len(dataset.window(rc.start_s, rc.duration_s))
    dataset.events()  # the first read of a stream parses it into the cache
    loaded = time.perf_counter()  # opening (and the first time simulating or caching) ends here
    if n_total < 2:
        raise EasVoError(
            f"{dataset.description}: the window start={rc.start_s} s, duration={rc.duration_s} s "
            f"holds {n_total} sample(s); at least 2 are needed"
        )

    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / "config.toml", config.to_toml())
    records: list[FrameRecord] = []
    edges: list[RelativeRotation] = []
    orb = OrbStats() if rc.orb_stats else None
    interrupted: BaseException | None = None
    with _FrameLog(out / "frames.csv" if out else None) as log, _progress(n_total, progress, rc) as bar, _terminate_as_interrupt():
        try:
            _track_all(dataset, rc, frontend, tracker, orb, records, edges, log, bar)
        except KeyboardInterrupt as exc:  # SIGINT, or SIGTERM: keep what was processed
            interrupted = exc
    if len(records) < 2:
        if interrupted is not None:
            raise interrupted
        raise EasVoError(f"{dataset.description}: fewer than 2 samples were processed")


    t = np.array([r.t for r in records])
    R_w_c = backend.solve(len(records), edges, t, dataset.imu)
    errors, offset = None, rc.time_offset_s
    if dataset.ground_truth is not None:
        if rc.time_offset_auto:
            offset = estimate_time_offset(t, edges, dataset.ground_truth)
        errors = rotation_errors(t, R_w_c, dataset.ground_truth, offset)
    elapsed = time.perf_counter() - started
    metrics = _metrics(config, dataset, records, errors, elapsed, loaded - started)
    metrics["time_offset_s"] = offset
    metrics["time_offset_estimated"] = rc.time_offset_auto and dataset.ground_truth is not None
    warnings = getattr(dataset, "warnings", None)
    metrics["data_warnings"] = warnings.lines() if warnings is not None else []
    metrics["partial"] = interrupted is not None
    if orb is not None:
        metrics.update(orb.summary())
    result = RunResult(t, R_w_c, records, edges, errors, metrics, getattr(backend, "causal", None))
    if out is not None:
        write_outputs(out, result, dataset.description)
    if interrupted is not None:
        raise interrupted
    return result


def _track_all(dataset, rc, frontend, tracker, orb, records, edges, log, bar) -> None:
    """The per-frame loop: frontend, tracker, and the frame's row in frames.csv."""
    for sample in dataset.samples(rc.start_s, rc.duration_s):
        image = frontend(sample)
        _check_image(image, dataset.camera, rc.frontend, sample)
        if orb is not None:
            orb.add(image)
        record, measured = tracker.process(image, sample.t)
        records.append(record)
        edges.extend(measured)
        log.write(record)
        bar.update(1)
        if record.index % 10 == 0:
            bar.set_postfix(nc=record.nc, refresh=False)


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C: the frames processed so far are written."""


@contextmanager
def _terminate_as_interrupt():
    """Within the block, SIGTERM raises Terminated (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _check_image(image, camera, frontend: str, sample) -> None:
    if (
        not isinstance(image, np.ndarray)
        or image.dtype != np.uint8
        or image.shape != (camera.height, camera.width)
    ):
        got = f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        raise EasVoError(
            f"frontend {frontend!r} returned {got} for frame {sample.index} (t={sample.t:.6f} s); "
            f"expected uint8 ({camera.height}, {camera.width})"
        )


def _metrics(config: ResolvedConfig, dataset: Dataset, records, errors, elapsed: float, load_s: float) -> dict:
    """Summary figures; speed is measured over the processing, after the dataset was opened."""
    pairs = records[1:]
    span = records[-1].t - records[0].t
    metrics = {
        "dataset": config.run.dataset,
        "frontend": config.run.frontend,
        "backend": config.run.backend,
        "frames": len(records),
        "frames_evaluated": int(errors.valid.sum()) if errors is not None else 0,
        "nc_mean": float(np.mean([r.nc for r in pairs])),
        "inliers_mean": float(np.mean([r.inliers for r in pairs])),
        "status_counts": dict(Counter(r.status for r in records)),
        "redetections": int(sum(r.redetected for r in pairs)),
        "sequence_s": float(span),
        "elapsed_s": float(elapsed),
        "load_s": float(load_s),
        "frames_per_s": len(records) / max(elapsed - load_s, 1e-9),
        "realtime_factor": float(span / max(elapsed - load_s, 1e-9)),
    }
    if errors is not None:
        metrics.update(errors.summary())
    return metrics


def write_outputs(out: Path, result: RunResult, description: str) -> None:
    """trajectory.tum, groundtruth.tum, metrics.json and rotation.png (each written atomically)."""
    zeros = np.zeros((len(result.t), 3))
    write_text_atomic(out / "trajectory.tum", format_tum(result.t, zeros, result.R_w_c))
    if result.causal_R_w_c is not None:
        write_text_atomic(out / "trajectory_causal.tum", format_tum(result.t, zeros, result.causal_R_w_c))
    errors = result.errors
    if errors is not None and errors.valid.any():
        write_text_atomic(out / "groundtruth.tum", format_tum(result.t[errors.valid], errors.p_w_c_gt, errors.R_w_c_gt))
    write_text_atomic(out / "metrics.json", json.dumps(result.metrics, indent=2, allow_nan=True) + "\n")
    from eas_vo.plots import plot_rotation

    with atomic_path(out / "rotation.png") as tmp:
        plot_rotation(tmp, result, title=f"{result.metrics['frontend']} + {result.metrics['backend']}: {description}")


def format_tum(t: np.ndarray, p: np.ndarray, R: np.ndarray) -> str:
    """TUM lines `t tx ty tz qx qy qz qw` (camera-to-world)."""
    q = quats_from_matrices(R) if len(R) else np.empty((0, 4))
    rows = np.column_stack([t, p, q])
    return "".join(
        f"{r[0]:.9f} {r[1]:.9f} {r[2]:.9f} {r[3]:.9f} {r[4]:.12f} {r[5]:.12f} {r[6]:.12f} {r[7]:.12f}\n"
        for r in rows
    )


class _FrameLog:
    """frames.csv, one row per frame, flushed as it goes so an interrupted run keeps its rows."""

    def __init__(self, path: Path | None):
        self.path = path

    def __enter__(self):
        self._fh = open(self.path, "w", newline="") if self.path else None
        if self._fh:
            self._writer = csv.writer(self._fh)
            self._writer.writerow(FRAMES_CSV_FIELDS)
        return self

    def write(self, r: FrameRecord) -> None:
        if self._fh:
            self._writer.writerow([r.index, f"{r.t:.9f}", r.nc, r.inliers, r.status, int(r.redetected)])
            self._fh.flush()

    def __exit__(self, *exc):
        if self._fh:
            self._fh.close()
        return False


def _progress(total: int, enabled: bool, rc):
    from tqdm import tqdm

    return tqdm(
        total=total,
        disable=not enabled,
        desc=f"{rc.frontend}+{rc.backend}",
        unit="frame",
        leave=False,
        dynamic_ncols=True,
    )
