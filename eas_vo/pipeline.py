"""One run, as its data flows: open -> track -> solve -> evaluate -> write.

dataset --Sample--> frontend --uint8 image--> tracker --records, edges--> backend
--R_w_c--> evaluation --> files. Each step is a function below; `run` strings them.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import itertools
import time
from collections import Counter
from dataclasses import dataclass, field
from dataclasses import replace as with_changes
from pathlib import Path

import numpy as np

from eas_vo import concurrency, registry
from eas_vo.config import TIME_OFFSET_LIMIT_S, ResolvedConfig
from eas_vo.datasets.calibration import check_frame_size
from eas_vo.datasets.recording import recording_clock_problems, time_source
from eas_vo.errors import EasVoError, Interrupted
from eas_vo.evaluation import (MAX_GAP_FRAMES, OFFSET_SEARCH_S, ImuAgreement, RotationErrors, estimate_time_offset, ground_truth_gap_limit_s,
                               imu_agreement, motion_errors, rotation_errors, scorable)
from eas_vo.geometry.rotations import geodesic_angle, matrix_to_rotvec, quats_from_matrices, rotvec_to_matrix
from eas_vo.imu_check import GyroVerdict, check_readings, judge_gyro, without
from eas_vo.io import atomic_path, clock_time, json_text, output_folder, write_text_atomic
from eas_vo.orb import OrbStats
from eas_vo.plugins import Backend, Dataset, Frontend, Tracker
from eas_vo.types import MAX_GAP_READINGS, FrameRecord, ImuSeries, RelativeRotation

FRAMES_CSV_FIELDS = ("index", "t", "nc", "inliers", "status", "redetected", "inlier_ratio", "residual_px", "reason",
                     "events", "contrast_gain")


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
    clock_origin_ns: int = 0  # the recording's clock at t = 0 (Dataset.clock_origin_ns), added back in files


RUN_FILES = ("config.toml", "identity.json", "frames.csv", "trajectory.tum", "metrics.json", "rotation.png")
"""What every finished run's folder holds (groundtruth.tum and trajectory_causal.tum when they apply)."""


def run(config: ResolvedConfig, out_dir: str | Path | None = None, progress: bool = False, replace: bool = False) -> RunResult:
    """Run the configured pipeline; with `out_dir`, write every output file there (a non-empty
    `out_dir` only if `replace` and it is an eas-vo output: io.output_folder).

    Ctrl-C (or SIGTERM turned into KeyboardInterrupt by the caller) during tracking
    keeps the frames processed so far: they are solved, evaluated and written, with
    `"partial": true`, and `Interrupted` is raised.
    """
    started = time.perf_counter()
    parts = open_pipeline(config)
    load_s = time.perf_counter() - started  # opening (and the first time simulating or caching)
    if out_dir is None:
        return _run_into(parts, config, None, progress, started, load_s)
    with output_folder(out_dir, replace) as staging:  # one writer; `out_dir` gets a whole run or a marked partial one
        return _run_into(parts, config, staging, progress, started, load_s, Path(out_dir))


def _run_into(parts: Pipeline, config: ResolvedConfig, out: Path | None, progress: bool, started: float, load_s: float,
              final: Path | None = None) -> RunResult:
    """Track, solve, evaluate and (with `out`) write there; `final` is where it will end up."""
    if out is not None:
        write_text_atomic(out / "config.toml", config.to_toml())
        write_text_atomic(out / "identity.json", json_text(run_identity(config)))
    try:
        tracked, verdict, retracked = _track_judging_the_gyro(parts, config, out, progress)
        still = _weaken_where_the_gyro_is_still(tracked, verdict, out / "frames.csv" if out else None,
                                                parts.dataset.clock_origin_ns)
        t = tracked.times
        agreement = None if parts.imu is None else imu_agreement(t, without(tracked.edges, still), parts.imu)
        fused = None if verdict is None or verdict.contradicts else parts.imu
        imu, imu_offset = _backend_imu(config, parts.backend, fused, agreement)
        solved = parts.backend.solve(len(t), tracked.edges, times=t, imu=imu)
        R_w_c = solved.R_w_c
        errors, offset, offset_estimated = evaluate(config, parts.dataset, t, R_w_c, tracked.edges)
        metrics = summarise(config, parts.dataset, tracked, errors, offset, offset_estimated,
                            time.perf_counter() - started, load_s, agreement, imu_offset, verdict, retracked)
        metrics["data_warnings"] = (parts.imu_warnings + metrics["data_warnings"] + list(parts.tracker.tracker_warnings)
                                  + list(solved.warnings))
        metrics["gyro_use"] = _gyro_use(parts, config, verdict, retracked)
        result = RunResult(t, R_w_c, tracked.records, tracked.edges, errors, metrics, solved.causal_R_w_c,
                           parts.dataset.clock_origin_ns)
        if out is not None:
            write_outputs(out, result, parts.dataset.label, config.origin)
    except KeyboardInterrupt as exc:  # before there was anything to evaluate, or while writing
        kept = f"{final} holds an incomplete run (no metrics.json): rerun with --overwrite" if final else ""
        raise Interrupted.keeping(exc, kept) from None
    if tracked.interrupted is not None:
        kept = f"the {len(t)} frames processed so far were written to {final} (metrics.json: partial)" if final else ""
        raise Interrupted.keeping(tracked.interrupted, kept) from None
    return result


def run_identity(config: ResolvedConfig) -> dict:
    """What made a run (identity.json): the eas-vo version and a hash of the code that ran
    (code_identity), the dataset's resolved location (an absolute path where it is one), its
    content identity (dataset_identity) and the whole resolved configuration. `compare`
    resumes a cell only when its folder's identity equals the one it would write now."""
    from eas_vo import __version__

    plugin, location = registry.resolve_dataset(config.run.dataset)
    path = Path(location).expanduser()
    plugins = [plugin] + [registry.get(kind, name) for kind, name in (
        ("frontends", config.run.frontend), ("trackers", config.run.tracker), ("backends", config.run.backend))]
    return {
        "eas_vo": __version__,
        "code": code_identity(tuple(sorted({cls.__module__.split(".")[0] for cls in plugins} | {"eas_vo"}))),
        "dataset": str(path.resolve()) if path.exists() else location,
        "dataset_content": dataset_identity(plugin, location),
        "config": config.to_toml(),
    }


@functools.cache
def code_identity(packages: tuple[str, ...]) -> str:
    """SHA-1 of the source (.py and .toml files) of `packages` and every subpackage they hold
    (eas-vo's own: its core and the four plugin packages; a third-party plugin's top-level
    package): a run made by other code, a tracker edited in place or another release, is
    another run whatever the version number says."""
    import hashlib
    import importlib

    files = {}  # each file by its dotted name in its package (the same whatever the install's layout)
    for name in packages:
        module = importlib.import_module(name)
        for sub in [module] + [importlib.import_module(f"{name}.{part}") for part in (
                "frontends", "trackers", "backends", "datasets", "configs") if name == "eas_vo"]:
            for folder in getattr(sub, "__path__", []):
                for path in Path(folder).rglob("*"):
                    if path.suffix in (".py", ".toml") and path.is_file():
                        files[".".join((sub.__name__, *path.relative_to(folder).parts))] = path
            if not hasattr(sub, "__path__") and getattr(sub, "__file__", None):
                files[sub.__name__ + ".py"] = Path(sub.__file__)
    digest = hashlib.sha1()
    for key in sorted(files):
        digest.update(key.encode() + b"\0" + files[key].read_bytes() + b"\0")
    return digest.hexdigest()


def dataset_identity(plugin: type, location: str):
    """The content identity of a dataset: for a file, its eventfile.file_identity; for a folder,
    that of each file in it and the times of its subfolders (a frame added, removed or renamed);
    for a name a plugin fetches, the checksum it is verified against; else None (a simulated
    sequence is a function of the configuration)."""
    from eas_vo.eventfile import file_identity

    path = Path(location).expanduser()
    if path.is_file():
        return list(file_identity(path))
    if path.is_dir():
        entries = sorted(p for p in path.iterdir() if not p.name.startswith("."))
        return {p.name: list(file_identity(p)) if p.is_file() else [p.stat().st_mtime_ns, p.stat().st_ctime_ns]
                for p in entries}
    return plugin.catalogue().get(location)


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
        raise EasVoError(f"frontend {rc.frontend!r} makes no images and tracker {rc.tracker!r} reads them; choose an image frontend")
    n_window = len(dataset.window(rc.start_s, rc.duration_s))
    if n_window < 2:
        raise EasVoError(
            f"{dataset.label}: the window start={rc.start_s} s, duration={rc.duration_s} s "
            f"holds {n_window} sample(s); at least 2 are needed"
        )
    _check_ground_truth_overlap(dataset, config.run, n_window)
    imu = None if dataset.imu is None else dataset.imu.in_camera_frame(rotvec_to_matrix(rc.imu_rotvec_cam), rc.imu_time_offset_s)
    parts = Pipeline(
        dataset=dataset,
        imu=imu,
        frontend=frontend_cls(config.frontend, dataset.camera),
        tracker=registry.get("trackers", rc.tracker)(config.tracker, dataset.camera, imu=imu),
        backend=registry.get("backends", rc.backend)(config.backend),
    )
    for kind, plugin in (("tracker", parts.tracker), ("backend", parts.backend)):
        if plugin.needs_imu and dataset.imu is None:
            raise EasVoError(f"{kind} {plugin.name!r} as configured needs an IMU and {dataset.label} has none "
                             f"(imu.txt, or the bag's IMU topic); change the {kind} settings or the dataset")
    if imu is not None and not (parts.tracker.uses_imu or parts.backend.uses_imu):
        parts.imu = None  # nothing reads it: neither checked nor judged
    if parts.imu is not None:
        window = dataset.frame_times()[dataset.window(rc.start_s, rc.duration_s)]
        parts.imu_warnings = check_readings(parts.imu, window, dataset.label, rc.imu_time_offset_s)
    return parts


def _track_judging_the_gyro(parts: Pipeline, config: ResolvedConfig, out: Path | None,
                            progress: bool) -> tuple[Tracked, GyroVerdict | None, bool]:
    """Track (frames.csv in `out`), and judge the gyro by the images (imu_check.judge_gyro).
    When the tracker predicted from a gyro the images contradict or cannot check (a wrong one
    misleads LK until nothing is measured confidently), track again without it: that tracking
    is kept if the first was contradicted or if it can judge the gyro, whose verdict it then
    gives. Returns the tracking kept, the verdict (None without a gyro) and whether the kept
    tracking is the one without the gyro."""
    tracked = track(parts, config, out / "frames.csv" if out else None, progress)
    verdict = None if parts.imu is None else judge_gyro(tracked.times, tracked.edges, parts.imu)
    if verdict is None or verdict.use == "used" or not parts.tracker.uses_imu or tracked.interrupted is not None:
        return tracked, verdict, False
    second_csv = out / "frames_without_gyro.csv" if out else None
    second = track(_without_imu(parts, config), config, second_csv, progress)
    second_verdict = judge_gyro(second.times, second.edges, parts.imu)
    if not (verdict.contradicts or second_verdict.can_tell):
        if second_csv:
            second_csv.unlink()
        return tracked, verdict, False
    if second_csv:
        second_csv.replace(out / "frames.csv")
    return second, verdict if verdict.contradicts else second_verdict, True


def _weaken_where_the_gyro_is_still(tracked: Tracked, verdict: GyroVerdict | None, frames_csv: Path | None,
                                    origin_ns: int = 0) -> set[int]:
    """Where the tracker's rotation turned while a gyro the images do not contradict read still
    (GyroVerdict.still): those frames become `weak` with that reason (frames.csv rewritten) and
    their edges' sigma at least the angle apart per axis (over sqrt(3)), so that a backend
    weighing edges by it trusts the gyro there. Returns those frames (none when the gyro is not used)."""
    if verdict is None or verdict.contradicts or not verdict.still:
        return set()
    apart = dict(verdict.still)
    for k, r in enumerate(tracked.records):
        if r.index in apart:
            reason = f"turns while the gyro reads still ({np.degrees(apart[r.index]):.2f} deg apart)"
            tracked.records[k] = dataclasses.replace(r, status="weak", reason=reason)
    for k, e in enumerate(tracked.edges):
        if e.j == e.i + 1 and not e.loop and e.j in apart:
            sigma = max(e.estimated_sigma_rad, apart[e.j] / np.sqrt(3.0))
            tracked.edges[k] = dataclasses.replace(e, estimated_sigma_rad=sigma)
    if frames_csv is not None:
        with atomic_path(frames_csv) as tmp, _FrameLog(tmp, origin_ns) as log:
            for r in tracked.records:
                log.write(r)
    return set(apart)


def _gyro_use(parts: Pipeline, config: ResolvedConfig, verdict: GyroVerdict | None, retracked: bool) -> str | None:
    """What read the gyro, for the run's summary (metrics.json `gyro_use`): the tracker (its
    Tracker.imu_use) unless the frames were tracked again without it, the backend (its
    Backend.imu_use) unless the images contradict it; None when nothing did."""
    if verdict is None or verdict.contradicts:
        return None
    uses = []
    if parts.tracker.uses_imu and not retracked:
        uses.append(f"by the {config.run.tracker} tracker as {parts.tracker.imu_use} "
                    f"(the rotations measured from {_tracked_from(config)})")
    if parts.backend.uses_imu:
        uses.append(f"by the {config.run.backend} backend as {parts.backend.imu_use}")
    return " and ".join(uses) or None


def _tracked_from(config: ResolvedConfig) -> str:
    """What the tracker measures its rotations from, for a message: the frontend's images, or
    the events for a tracker that reads no images (Tracker.reads_images)."""
    if registry.get("trackers", config.run.tracker).reads_images:
        return f"the {config.run.frontend} images"
    return "the events"


def _without_imu(parts: Pipeline, config: ResolvedConfig) -> Pipeline:
    """The same pipeline with a tracker that does not see the IMU."""
    tracker = registry.get("trackers", config.run.tracker)(config.tracker, parts.dataset.camera, imu=None)
    parts.frontend.reset()
    return Pipeline(parts.dataset, parts.imu, parts.frontend, tracker, parts.backend, parts.imu_warnings)


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
    where = f"{time_source(dataset, 'ground-truth')}: the ground truth ({len(gt.t)} poses, {gt.t[0]:.3f}-{gt.t[-1]:.3f} s)"
    if np.any((t >= gt.t[0]) & (t <= gt.t[-1])):
        widest = float(np.max(np.diff(gt.t)))
        raise EasVoError(f"{where} scores none of the {n_window} frame times of the window ({t[0]:.3f}-{t[-1]:.3f} s): "
                         f"its poses lie up to {widest:.3g} s apart, and it is interpolated across gaps of at most "
                         f"{ground_truth_gap_limit_s(gt.t, t):.3g} s ({MAX_GAP_READINGS} of its median sample intervals, "
                         f"and {MAX_GAP_FRAMES} of the frames' at most)")
    gap_s = float(dataset.frame_times()[0] - gt.t[0])
    hint = ("check --time-offset, --start and --duration" if abs(gap_s) <= TIME_OFFSET_LIMIT_S else
            f"its clock is not the recording's: put it there with --set dataset.ground_truth_time_offset_s=S "
            f"(S = {gap_s:.6f} would start both together)")
    raise EasVoError(f"{where} covers none of the {n_window} frame times of the window ({t[0]:.3f}-{t[-1]:.3f} s with "
                     f"the time offset {rc.time_offset_s:+g} s); {hint}")


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
            record, edges = with_changes(record, status="lost", inliers=0, reason="the same image as the previous frame"), []
        tracked.records.append(record)
        tracked.edges.extend(edges)
        log.write(record)
        bar.update(1)
        if record.index % 10 == 0:
            bar.set_postfix(nc=record.nc, refresh=False)

    with _FrameLog(frames_csv, parts.dataset.clock_origin_ns) as log, _progress(n_window, progress, rc) as bar:
        try:
            for position, sample in enumerate(concurrency.ahead(parts.dataset.samples(rc.start_s, rc.duration_s))):  # the next one read meanwhile
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


def evaluate(config: ResolvedConfig, dataset: Dataset, t: np.ndarray, R_w_c: np.ndarray,
             edges) -> tuple[RotationErrors | None, float, bool]:
    """Per-frame rotation errors against the dataset's ground truth (None without it), the
    time offset [s] used, and whether it was estimated from the edges (run.time_offset_auto;
    else, or when the estimate is impossible, the configured one)."""
    rc = config.run
    if dataset.ground_truth is None:
        return None, rc.time_offset_s, False
    estimated = estimate_time_offset(t, edges, dataset.ground_truth) if rc.time_offset_auto else None
    offset = rc.time_offset_s if estimated is None else estimated
    return rotation_errors(t, R_w_c, dataset.ground_truth, offset), offset, estimated is not None


def summarise(config: ResolvedConfig, dataset: Dataset, tracked: Tracked, errors, offset: float, offset_estimated: bool,
              elapsed: float, load_s: float, agreement: ImuAgreement | None = None, imu_offset: float | None = None,
              verdict: GyroVerdict | None = None, retracked: bool = False) -> dict:
    """metrics.json: accuracy, tracking and speed figures; speed is measured over the
    processing, after the dataset was opened. `offset` [s]: the ground truth's time offset the
    errors were measured with (`offset_estimated`: from the edges). With an IMU: its check
    against the tracked rotations (`agreement`), the time offset [s] the backend read it with, and
    the images' verdict on it (`retracked`: the frames were tracked again without it)."""
    records = tracked.records
    pairs = records[1:]
    span = records[-1].t - records[0].t
    processing = max(elapsed - load_s, 1e-9)
    metrics = {
        "dataset": config.run.dataset,
        "frontend": config.run.frontend,
        "tracker": config.run.tracker,
        "backend": config.run.backend,
        "frames": len(records),
        "frames_evaluated": int(errors.valid.sum()) if errors is not None else 0,
        "nc_mean": float(np.mean([r.nc for r in pairs])),
        "inliers_mean": float(np.mean([r.inliers for r in pairs])),
        "status_counts": dict(Counter(r.status for r in records)),
        "status_reasons": {status: dict(Counter(r.reason.split(" (")[0] for r in records if r.status == status and r.reason))
                           for status in ("weak", "lost")},
        "redetections": int(sum(r.redetected for r in pairs)),
        "edge_count": len(tracked.edges),
        "loop_count": int(sum(e.loop for e in tracked.edges)) if tracked.closes_loops else None,
        "sequence_s": float(span),
        "elapsed_s": float(elapsed),
        "load_s": float(load_s),
        "frames_per_s": len(records) / processing,
        "realtime_factor": float(span / processing),
    }
    if errors is not None:
        metrics.update(errors.summary())
        metrics.update(errors.coverage(tracked.times))
        metrics.update(motion_errors(tracked.times, errors, tracked.edges))
    metrics["time_offset_s"] = offset
    metrics["time_offset_estimated"] = offset_estimated
    reclocked = imu_offset is not None and imu_offset != config.run.imu_time_offset_s
    if imu_offset is not None:
        metrics["imu_time_offset_s"] = imu_offset
        metrics["imu_time_offset_estimated"] = reclocked
    imu_findings = _imu_disagrees(config, agreement, reclocked)
    metrics["gyro"] = None if verdict is None else verdict.use
    metrics["data_warnings"] = (dataset.data_warnings() + _events_end_early(config, dataset, tracked.times)
                                + ([] if errors is None else errors.coverage_warning(tracked.times))
                                + _offset_not_estimated(config, dataset, tracked, offset, offset_estimated)
                                + (imu_findings if verdict is None else verdict.warnings(retracked, imu_findings)))
    metrics["partial"] = tracked.interrupted is not None
    if tracked.orb is not None:
        metrics.update(tracked.orb.summary())
    return metrics


def _offset_not_estimated(config: ResolvedConfig, dataset: Dataset, tracked: Tracked, offset: float,
                          estimated: bool) -> list[str]:
    """A warning when run.time_offset_auto could not estimate the offset (evaluation.estimate_time_offset)."""
    if not config.run.time_offset_auto or dataset.ground_truth is None or estimated:
        return []
    return [f"the time offset could not be estimated from the {len(tracked.edges)} measured rotations (fewer than 5; "
            f"the ground truth spanning fewer than half of them at every offset within {OFFSET_SEARCH_S * 1e3:g} ms; or no "
            "clear best offset within it: a still camera, identical frames, or a true offset beyond the search): "
            f"the errors are measured with {offset:+g} s"]


def _events_end_early(config: ResolvedConfig, dataset: Dataset, times: np.ndarray) -> list[str]:
    """A warning when an event frontend's or tracker's frames outlast the events, or there are
    none (a still camera without noise; more often events that were not recorded or not found)."""
    frontend, tracker = config.run.frontend, config.run.tracker
    if registry.get("frontends", frontend).needs_events:
        what = f"the {frontend} images"
    elif registry.get("trackers", tracker).needs_events:
        what = f"the {tracker} tracker's samples"
    else:
        return []
    events = dataset.events()
    if len(events) == 0:
        return [f"{dataset.label} holds no events: {what} of its {len(times)} frames hold none"]
    last = float(events["t"][-1])
    late = int(np.sum(times > last))
    if late == 0:
        return []
    return [f"{dataset.label}: the events end at {last:.3f} s, before {late} of the {len(times)} frames: "
            f"{what.replace('the ', 'their ', 1)} hold no events"]


#: Above this angle [deg] the gyro and the tracker disagree on the axes: on correctly mounted
#: simulated IMUs the fit found 0.6-5.1 deg (twelve sequences, best.toml and paper.toml); a wrong
#: axis convention is 90 or 180 deg.
IMU_DISAGREEMENT_DEG = 10.0
#: The gyro's clock is off when reading it this much later or earlier [s] explains the tracked
#: rotations clearly better (CLOCK_GAIN: the median residual at most 90 % of the configured
#: clock's): on twelve simulated IMUs read on time (best.toml and paper.toml, eas) the search
#: found -7.8 to +3.7 ms at 93 % or more (the images' own lag); on the real excerpt with a gyro
#: made from its ground truth (9 ms behind its frames) 8.9-9.2 ms at about 60 %.
CLOCK_OFF_S = 0.002
CLOCK_GAIN = 0.9
#: Below this spread (ImuAgreement.spread) the camera turned about one axis only and the fit
#: cannot tell how the gyro is turned about it: under 0.05 for a pure pan (a test), 0.5-0.65 on
#: hand-held sequences (synthetic:default, seed 41, a 30 s one, the real excerpt).
MIN_SPREAD = 0.2
#: The axes are taken for off (beyond IMU_DISAGREEMENT_DEG) only beyond this many standard
#: deviations of the fit too (ImuAgreement.turned_sigma_deg), so that a short or noisy sequence
#: says nothing it cannot tell. The images' errors are
#: correlated from pair to pair (lag, blur), which the scatter understates: on right IMUs
#: (2 s simulated sequences at 240x180, 346x260 and 640x480, eas and histeq) the fit was 0.8-11
#: deg off, up to 4.3 of its sigmas; an axis swap 65.
AXES_SIGMAS = 5.0
#: A fit this close [deg] to an axis swap or flip is taken for it (those are 90 deg apart; a
#: quarter turn misread on a 2 s sequence was fitted 10 deg off).
AXES_SNAP_DEG = 20.0


def _axis_rotations() -> list[np.ndarray]:
    """The 24 rotations that permute and flip axes: how IMU axis conventions differ."""
    rotations = []
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            R = np.zeros((3, 3))
            R[range(3), order] = signs
            if np.linalg.det(R) > 0:
                rotations.append(R)
    return rotations


def _conclusive(agreement: ImuAgreement | None) -> bool:
    """Whether the check can say anything: at least half the frame pairs (and 20) agree."""
    return agreement is not None and agreement.agreeing >= max(20, agreement.pairs / 2)


def _axes_off(agreement: ImuAgreement | None) -> bool:
    """Whether the gyro agrees with the images only turned by more than IMU_DISAGREEMENT_DEG
    and AXES_SIGMAS times the fit's own uncertainty (about more than one axis: MIN_SPREAD)."""
    return _conclusive(agreement) and agreement.spread >= MIN_SPREAD and (
        agreement.mirrored or agreement.turned_deg > max(IMU_DISAGREEMENT_DEG, AXES_SIGMAS * agreement.turned_sigma_deg))


def _clock_is_off(agreement: ImuAgreement | None) -> bool:
    """Whether the images clearly ask for the gyro read CLOCK_OFF_S or more off its clock.
    Not judged while the axes are off: a tracker predicting from a wrongly turned gyro leans
    its tracks towards it, which reads as a clock offset (12 ms on a 2 s test sequence)."""
    return (_conclusive(agreement) and not _axes_off(agreement) and abs(agreement.clock_shift_s) >= CLOCK_OFF_S
            and agreement.residual_rad <= CLOCK_GAIN * agreement.residual_unshifted_rad)


def _reclocked(config: ResolvedConfig, backend: Backend, agreement: ImuAgreement | None) -> bool:
    """Whether run.imu_time_offset_auto re-times the IMU for this backend: it reads the IMU,
    and the images clearly ask for another clock, found within the search."""
    return (config.run.imu_time_offset_auto and backend.uses_imu and _clock_is_off(agreement)
            and not agreement.shift_at_limit and not _images_lag(config))


def _images_lag(config: ResolvedConfig) -> bool:
    """Whether the run's frontend shows the past (Frontend.shows_the_past): a clock shift is then
    the images' lag. Re-timing the gyro to it made best.toml worse with `ts` (synthetic:default
    0.038 -> 0.112 rad, seed 1 0.049 -> 0.429): the fused trajectory then lags the frames."""
    return registry.get("frontends", config.run.frontend).shows_the_past


def _backend_imu(config: ResolvedConfig, backend: Backend, imu: ImuSeries | None,
                 agreement: ImuAgreement | None) -> tuple[ImuSeries | None, float | None]:
    """The IMU the backend gets and the time offset [s] it is read with: as configured, or
    (_reclocked) on the clock the images ask for. With an online backend that clock was found
    over the whole sequence, so its causal estimates are no longer strictly causal."""
    if imu is None:
        return None, None
    configured = config.run.imu_time_offset_s
    if not _reclocked(config, backend, agreement):
        return imu, configured
    shift = agreement.clock_shift_s
    return ImuSeries(imu.t - shift, imu.acc, imu.gyro), configured + shift


def _imu_disagrees(config: ResolvedConfig, agreement: ImuAgreement | None, reclocked: bool) -> list[str]:
    """Warnings when the gyro's rotations agree with the tracker's only once turned by more
    than IMU_DISAGREEMENT_DEG (and the motion turned about more than one axis), or (unless
    `reclocked`: _reclocked took care of it) clearly better read CLOCK_OFF_S or more off its
    configured clock (judged once the axes agree), naming the run.imu_rotvec_cam (an axis swap
    or flip within AXES_SNAP_DEG of the fit) or run.imu_time_offset_s the data suggest. Silent
    when fewer than half the frame pairs agree with any rotation, which says nothing either way."""
    warnings = []
    if _axes_off(agreement):
        warnings.append(_imu_axes_warning(config, agreement))
    if _clock_is_off(agreement) and not reclocked:
        warnings.append(_imu_clock_warning(config, agreement))
    return warnings


def _imu_clock_warning(config: ResolvedConfig, agreement: ImuAgreement) -> str:
    """What the clock check says. The shift is between the gyro and the time the images show:
    the IMU's clock, or, for a frontend that shows the past (_images_lag: a time surface, `ts`
    on a gyro read on time was found 14-18 ms early), the images' lag."""
    shift, configured = agreement.clock_shift_s, config.run.imu_time_offset_s
    at_least = "at least " if agreement.shift_at_limit else ""
    found = (f"the gyro agrees best with the tracked rotations read {at_least}{abs(shift) * 1e3:.1f} ms "
             f"{'later' if shift > 0 else 'earlier'} than configured (median residual {np.degrees(agreement.residual_rad):.2f} "
             f"against {np.degrees(agreement.residual_unshifted_rad):.2f} deg)")
    if _images_lag(config):
        return (f"{found}: the {config.run.frontend} images show the past, so this is taken for their lag and the "
                f"IMU's clock is kept; to check the clock itself, run a frontend of the present (e.g. eas)")
    return (f"{found}: the IMU's clock, or the time {_tracked_from(config)} show, is off by that; "
            f"run.imu_time_offset_s = {at_least}{configured + shift:.4f} would match them, not {configured:.10g}")


def _imu_axes_warning(config: ResolvedConfig, agreement) -> str:
    """What the axes check says: how far the gyro is turned and the place that explains it."""
    R_configured = rotvec_to_matrix(config.run.imu_rotvec_cam)
    R_imu_cam = R_configured @ agreement.R
    axes = min(_axis_rotations(), key=lambda R: geodesic_angle(R, R_imu_cam))
    off = np.degrees(geodesic_angle(axes, R_imu_cam))
    moved = agreement.mirrored or np.degrees(geodesic_angle(axes, R_configured)) > IMU_DISAGREEMENT_DEG
    if off < AXES_SNAP_DEG and moved:
        kind = "the identity" if np.allclose(axes, np.eye(3)) else "axes swapped or flipped"
        looks, how = axes, f"{kind}, {off:.1f} deg from the fit"
    else:
        looks, how = R_imu_cam, "fitted"

    def vector(v) -> str:
        return "[" + ", ".join(f"{float(x) + 0.0:.10g}" if abs(x) > 1e-12 else "0" for x in v) + "]"

    if agreement.mirrored:
        return (f"the gyro agrees with the tracked rotations only with its rates negated ({agreement.agreeing} of "
                f"{agreement.pairs} frame pairs): its axes are mirrored (a left-handed convention), which no "
                f"run.imu_rotvec_cam undoes; negate its rates in the file, then run.imu_rotvec_cam = "
                f"{vector(matrix_to_rotvec(looks))} ({how})")
    return (f"the gyro agrees with the tracked rotations only turned by {agreement.turned_deg:.1f} deg ({agreement.agreeing} of "
            f"{agreement.pairs} frame pairs): the IMU looks mounted as run.imu_rotvec_cam = {vector(matrix_to_rotvec(looks))} "
            f"({how}), not {vector(config.run.imu_rotvec_cam)}; check it and the camera calibration")


def write_outputs(out: Path, result: RunResult, label: str, origin: str = "") -> None:
    """trajectory.tum, groundtruth.tum, metrics.json and rotation.png (each written atomically);
    `label` names the dataset and `origin` the configuration (ResolvedConfig.origin) in its title."""
    zeros = np.zeros((len(result.t), 3))
    origin_ns = result.clock_origin_ns
    write_text_atomic(out / "trajectory.tum", format_tum(result.t, zeros, result.R_w_c, origin_ns))
    if result.causal_R_w_c is not None:
        write_text_atomic(out / "trajectory_causal.tum", format_tum(result.t, zeros, result.causal_R_w_c, origin_ns))
    errors = result.errors
    if errors is not None and errors.valid.any():
        write_text_atomic(out / "groundtruth.tum", format_tum(result.t[errors.valid], errors.p_w_c_gt, errors.R_w_c_gt, origin_ns))
    write_text_atomic(out / "metrics.json", json_text(result.metrics))
    from eas_vo.plots import plot_rotation

    with atomic_path(out / "rotation.png") as tmp:
        m = result.metrics
        plot_rotation(tmp, result, title=f"{m['frontend']} + {m['tracker']} + {m['backend']} ({origin or 'defaults'}): {label}")


def format_tum(t: np.ndarray, p: np.ndarray, R: np.ndarray, origin_ns: int = 0) -> str:
    """TUM lines `t tx ty tz qx qy qz qw` (camera-to-world); t [s] after the clock origin `origin_ns`."""
    q = quats_from_matrices(R) if len(R) else np.empty((0, 4))
    rows = np.column_stack([p, q])
    return "".join(
        f"{clock_time(ti, origin_ns)} {r[0]:.9f} {r[1]:.9f} {r[2]:.9f} {r[3]:.12f} {r[4]:.12f} {r[5]:.12f} {r[6]:.12f}\n"
        for ti, r in zip(t, rows)
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


def check_image(image, camera, frontend: str, sample) -> None:
    """A frontend's output must be a uint8 image of sensor size (H, W): else one error line."""
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


class _FrameLog:
    """frames.csv, one row per frame, flushed as it goes so an interrupted run keeps its rows."""

    def __init__(self, path: Path | None, origin_ns: int = 0):
        self.path = path
        self.origin_ns = origin_ns

    def __enter__(self):
        self._fh = open(self.path, "w", newline="") if self.path else None
        if self._fh:
            self._writer = csv.writer(self._fh, lineterminator="\n")
            self._writer.writerow(FRAMES_CSV_FIELDS)
        return self

    def write(self, r: FrameRecord) -> None:
        if self._fh:
            self._writer.writerow([r.index, clock_time(r.t, self.origin_ns), r.nc, r.inliers, r.status, int(r.redetected),
                                   f"{r.inlier_ratio:.4f}", f"{r.residual_px:.4f}", r.reason, r.events,
                                   f"{r.contrast_gain:.4f}"])
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
        desc=f"{rc.frontend}+{rc.tracker}+{rc.backend}",
        unit="frame",
        leave=False,
        dynamic_ncols=True,
    )
