"""One run, as its data flows: open -> track -> assess the gyro -> solve -> evaluate -> write.

dataset --Sample--> frontend --uint8 image--> tracker --records, edges--> backend
--R_w_c--> evaluation --> files. `run` strings the steps of this package together."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from eas_vo import registry
from eas_vo.config import ResolvedConfig
from eas_vo.errors import EasVoError, Interrupted
from eas_vo.geometry.uncertainty import chain_covariance, consecutive_steps
from eas_vo.imu.policy import GyroDecision, GyroSetup, assess
from eas_vo.io.atomic import atomic_path, json_text, write_text_atomic
from eas_vo.io.outputs import output_folder
from eas_vo.pipeline.identity import run_identity
from eas_vo.pipeline.outputs import RunResult, write_outputs
from eas_vo.pipeline.parts import Pipeline, open_pipeline
from eas_vo.pipeline.summary import evaluate, summarise
from eas_vo.pipeline.tracking import FrameLog, Tracked, track
from eas_vo.plugins import BackendResult
from eas_vo.types import RelativeRotation


def run(
    config: ResolvedConfig, out_dir: str | Path | None = None, progress: bool = False, replace: bool = False
) -> RunResult:
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


def _run_into(
    parts: Pipeline,
    config: ResolvedConfig,
    out: Path | None,
    progress: bool,
    started: float,
    load_s: float,
    final: Path | None = None,
) -> RunResult:
    """Track, assess the gyro, solve, evaluate and (with `out`) write there; `final` is where it will end up."""
    if out is not None:
        write_text_atomic(out / "config.toml", config.to_toml())
        write_text_atomic(out / "identity.json", json_text(run_identity(config)))
    try:
        tracked, gyro = _track_and_assess_gyro(parts, config, out, progress)
        t = tracked.times
        solved = parts.backend.solve(len(t), tracked.edges, times=t, imu=gyro.backend_imu)
        if not isinstance(solved, BackendResult):
            raise EasVoError(
                f"backend {config.run.backend!r} returned {type(solved).__name__}: Backend.solve returns "
                "an eas_vo.plugins.BackendResult (docs/plugins.md)"
            )
        R_w_c = solved.R_w_c
        covariance = _checked_covariance(solved.covariance, len(t), config.run.backend)
        evaluation = evaluate(config, parts.dataset, t, R_w_c, tracked.edges)
        metrics = summarise(config, parts.dataset, tracked, evaluation, time.perf_counter() - started, load_s, gyro)
        metrics["data_warnings"] = (
            parts.imu_warnings + metrics["data_warnings"] + list(parts.tracker.tracker_warnings) + list(solved.warnings)
        )
        metrics["gyro_use"] = gyro.readers
        result = RunResult(
            t,
            R_w_c,
            tracked.records,
            tracked.edges,
            evaluation.errors,
            metrics,
            solved.causal_R_w_c,
            parts.dataset.clock_origin_ns,
            covariance,
            chain_covariance(len(t), tracked.edges),
        )
        if out is not None:
            write_outputs(out, result, parts.dataset.label, config.origin)
    except KeyboardInterrupt as exc:  # before there was anything to evaluate, or while writing
        kept = f"{final} holds an incomplete run (no metrics.json): rerun with --overwrite" if final else ""
        raise Interrupted.keeping(exc, kept) from None
    if tracked.interrupted is not None:
        kept = f"the {len(t)} frames processed so far were written to {final} (metrics.json: partial)" if final else ""
        raise Interrupted.keeping(tracked.interrupted, kept) from None
    return result


def _checked_covariance(covariance, n_frames: int, backend: str) -> np.ndarray | None:
    """A backend's covariance as BackendResult promises it, (n_frames, 3, 3) [rad^2], or None;
    anything else is a one-line error naming the backend."""
    if covariance is None:
        return None
    covariance = np.asarray(covariance, dtype=float)
    if covariance.shape != (n_frames, 3, 3):
        raise EasVoError(
            f"backend {backend!r} returned a covariance of shape {covariance.shape}: BackendResult.covariance is "
            f"({n_frames}, 3, 3), a 3x3 covariance [rad^2] per frame, or None (docs/plugins.md)"
        )
    return covariance


def gyro_setup(config: ResolvedConfig, parts: Pipeline) -> GyroSetup:
    """What the gyro's policy (imu.policy) needs to know of this run."""
    rc = config.run
    return GyroSetup(
        rc.imu_rotvec_cam,
        rc.imu_time_offset_s,
        rc.imu_time_offset_auto,
        rc.frontend,
        rc.tracker,
        rc.backend,
        images_lag=parts.frontend.shows_the_past,
        tracker_reads_images=parts.tracker.reads_images,
        tracker_uses_imu=parts.tracker.uses_imu,
        tracker_imu_use=parts.tracker.imu_use,
        backend_uses_imu=parts.backend.uses_imu,
        backend_imu_use=parts.backend.imu_use,
    )


def _track_and_assess_gyro(
    parts: Pipeline, config: ResolvedConfig, out: Path | None, progress: bool
) -> tuple[Tracked, GyroDecision]:
    """Track (frames.csv in `out`) and ask the gyro's policy once (imu.policy.assess), which may
    have the frames tracked again without the gyro (frames_without_gyro.csv, frames.csv if kept);
    frames where the scene moved while the gyro read still become weak (frames.csv rewritten)."""
    frames_csv = out / "frames.csv" if out else None
    second_csv = out / "frames_without_gyro.csv" if out else None
    tracked = track(parts, config, frames_csv, progress)
    without_gyro: list[Tracked] = []

    def retrack() -> tuple[np.ndarray, list[RelativeRotation]]:
        without_gyro.append(track(_without_imu(parts, config), config, second_csv, progress))
        return without_gyro[0].times, without_gyro[0].edges

    gyro = assess(
        parts.imu,
        tracked.times,
        tracked.edges,
        gyro_setup(config, parts),
        retrack if tracked.interrupted is None else None,
    )
    if without_gyro and second_csv:
        if gyro.retrack:
            second_csv.replace(frames_csv)
        else:
            second_csv.unlink()
    if gyro.retrack:
        tracked = without_gyro[0]
    if gyro.still:
        tracked.records, tracked.edges = gyro.weakened(tracked.records, tracked.edges)
        if frames_csv is not None:
            steps = consecutive_steps(tracked.edges)
            with atomic_path(frames_csv) as tmp, FrameLog(tmp, parts.dataset.clock_origin_ns) as log:
                for r in tracked.records:
                    log.write(r, steps.get(r.index))
    return tracked, gyro


def _without_imu(parts: Pipeline, config: ResolvedConfig) -> Pipeline:
    """The same pipeline with a tracker that does not see the IMU."""
    tracker = registry.get("trackers", config.run.tracker)(config.tracker, parts.dataset.camera, imu=None)
    parts.frontend.reset()
    return Pipeline(parts.dataset, parts.imu, parts.frontend, tracker, parts.backend, parts.imu_warnings)
