"""A run's figures (metrics.json): errors against the ground truth, tracking counts, speed, and
the warnings about its data."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from eas_vo import registry
from eas_vo.config import ResolvedConfig
from eas_vo.evaluation.ape import RotationErrors, rotation_errors
from eas_vo.evaluation.motion import motion_errors
from eas_vo.evaluation.time_offset import OFFSET_SEARCH_S, estimate_time_offset
from eas_vo.imu.policy import GyroDecision
from eas_vo.pipeline.tracking import Tracked
from eas_vo.plugins import Dataset


@dataclass(frozen=True)
class Evaluation:
    """A trajectory against the dataset's ground truth: the per-frame rotation errors (None
    without ground truth), the ground truth's time offset [s] they were measured with, and
    whether that offset was estimated from the edges (run.time_offset_auto)."""

    errors: RotationErrors | None
    time_offset_s: float
    offset_estimated: bool = False


def evaluate(config: ResolvedConfig, dataset: Dataset, t: np.ndarray, R_w_c: np.ndarray, edges) -> Evaluation:
    """The trajectory `R_w_c` at frame times `t` [s] against the dataset's ground truth, with the
    configured time offset or (run.time_offset_auto, when possible) one estimated from the edges."""
    rc = config.run
    if dataset.ground_truth is None:
        return Evaluation(None, rc.time_offset_s)
    estimated = estimate_time_offset(t, edges, dataset.ground_truth) if rc.time_offset_auto else None
    offset = rc.time_offset_s if estimated is None else estimated
    return Evaluation(rotation_errors(t, R_w_c, dataset.ground_truth, offset), offset, estimated is not None)


def summarise(
    config: ResolvedConfig,
    dataset: Dataset,
    tracked: Tracked,
    evaluation: Evaluation,
    elapsed: float,
    load_s: float,
    gyro: GyroDecision,
) -> dict:
    """metrics.json: accuracy (`evaluation`), tracking and speed figures, and what was decided
    about the gyro; speed is measured over the processing (`elapsed` [s] less the `load_s` [s]
    of opening the dataset)."""
    errors, offset, offset_estimated = evaluation.errors, evaluation.time_offset_s, evaluation.offset_estimated
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
        "status_reasons": {
            status: dict(Counter(r.reason.split(" (")[0] for r in records if r.status == status and r.reason))
            for status in ("weak", "lost")
        },
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
    if gyro.imu_time_offset_s is not None:
        metrics["imu_time_offset_s"] = gyro.imu_time_offset_s
        metrics["imu_time_offset_estimated"] = gyro.reclocked
    metrics["gyro"] = gyro.use
    metrics["data_warnings"] = (
        dataset.data_warnings()
        + _events_end_early(config, dataset, tracked.times)
        + ([] if errors is None else errors.coverage_warning(tracked.times))
        + _offset_not_estimated(config, dataset, tracked, offset, offset_estimated)
        + list(gyro.warnings)
    )
    metrics["partial"] = tracked.interrupted is not None
    if tracked.orb is not None:
        metrics.update(tracked.orb.summary())
    return metrics


def _offset_not_estimated(
    config: ResolvedConfig, dataset: Dataset, tracked: Tracked, offset: float, estimated: bool
) -> list[str]:
    """A warning when run.time_offset_auto could not estimate the offset (evaluation.estimate_time_offset)."""
    if not config.run.time_offset_auto or dataset.ground_truth is None or estimated:
        return []
    return [
        f"the time offset could not be estimated from the {len(tracked.edges)} measured rotations (fewer than 5; "
        f"the ground truth spanning fewer than half of them at every offset within {OFFSET_SEARCH_S * 1e3:g} ms; or no "
        "clear best offset within it: a still camera, identical frames, or a true offset beyond the search): "
        f"the errors are measured with {offset:+g} s"
    ]


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
    return [
        f"{dataset.label}: the events end at {last:.3f} s, before {late} of the {len(times)} frames: "
        f"{what.replace('the ', 'their ', 1)} hold no events"
    ]
