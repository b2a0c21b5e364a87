"""A trajectory another tool wrote (ORB-SLAM's, CMax-SLAM's, any TUM file, or poses in memory)
scored against a dataset's ground truth as evo_ape scores it, and its row of the paper's Table 2."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from eas_vo.errors import EasVoError
from eas_vo.io.atomic import json_text, write_text_atomic
from eas_vo.io.outputs import output_folder
from eas_vo.io.text import figure_text, markdown_cell
from eas_vo.types import PoseSeries

if TYPE_CHECKING:
    from eas_vo.plugins import Dataset

#: What an estimate is: a TUM file (on the recording's own clock), or camera-to-world poses in
#: memory on the dataset's clock (seconds from its clock origin, as a run's times).
Estimate = str | Path | PoseSeries


def evaluate_estimate(
    dataset: str | Dataset,
    estimate: Estimate,
    align: str,
    max_diff_s: float,
    out: str | Path | None = None,
    label: str | None = None,
    replace: bool = False,
) -> dict:
    """Score an external trajectory against the ground truth of `dataset` (a `--dataset` value
    or an opened dataset) (evaluation.trajectory_ape); with `out`, write metrics.json,
    table2_row.md, groundtruth.tum (what it was compared with) and estimate_aligned.tum. Returns
    the metrics."""
    from eas_vo.evaluation.trajectory import ALIGNMENTS, trajectory_ape
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum

    if align not in ALIGNMENTS:
        raise EasVoError(f"--align {align!r}: choose one of {', '.join(ALIGNMENTS)}")
    dataset = _opened(dataset)
    poses, gt = _estimate_and_truth(dataset, estimate)
    origin_ns = dataset.clock_origin_ns
    try:
        ape = trajectory_ape(gt, poses, align, max_diff_s)
    except ValueError as exc:
        raise EasVoError(f"{_name(estimate)}: {exc}") from None
    label = label or (Path(_file(estimate)).stem if _file(estimate) else "estimate")
    metrics = {
        "estimate": _file(estimate),
        "dataset": dataset.label,
        "align": align,
        "max_diff_s": max_diff_s,
        "estimate_poses": len(poses.t),
        **ape.summary(),
        **_coverage(poses.t, gt.t, ape.summary()),
    }
    if out is not None:
        with output_folder(out, replace) as staging:
            write_text_atomic(staging / "metrics.json", json_text(metrics))
            write_text_atomic(staging / "table2_row.md", table2_row(label, metrics))
            write_text_atomic(
                staging / "groundtruth.tum", format_tum(gt.t, gt.p_w_c, matrices_from_quats(gt.q_w_c), origin_ns)
            )
            aligned = ape.aligned(poses.p_w_c, matrices_from_quats(poses.q_w_c))
            write_text_atomic(staging / "estimate_aligned.tum", format_tum(poses.t, *aligned, origin_ns))
    return metrics


def _opened(dataset: str | Dataset) -> Dataset:
    """The dataset a `--dataset` value opens (registry.open_dataset), or `dataset` itself when open."""
    from eas_vo.registry import open_dataset

    return open_dataset(dataset) if isinstance(dataset, str) else dataset


def _file(estimate: Estimate) -> str | None:
    """The estimate's file as given; None for poses in memory."""
    return None if isinstance(estimate, PoseSeries) else str(estimate)


def _name(estimate: Estimate) -> str:
    """The estimate in messages: its file, or "the estimate" for poses in memory."""
    return _file(estimate) or "the estimate"


def _estimate_and_truth(dataset, estimate: Estimate, ordered: bool = True):
    """(the estimate on the dataset's clock [s], its ground truth): a TUM file holds the
    recording's own times, poses in memory and the ground truth are read after its clock origin.
    `ordered` False takes a file's poses sorted by time (poses in memory always are), the first of
    any repeated time (a frame skipped as the same image as the previous keeps its pose). Raises
    EasVoError for a dataset without ground truth or an estimate in another clock unit."""
    from eas_vo.datasets.recording import clock_unit_problems, time_source
    from eas_vo.io.tum import read_tum

    gt = dataset.ground_truth
    if gt is None:
        raise EasVoError(f"{dataset.label}: has no ground truth to evaluate against")
    if isinstance(estimate, PoseSeries):
        given, origin_s = estimate, 0.0
    else:
        given, origin_s = read_tum(estimate, ordered=ordered), dataset.clock_origin_ns / 1e9
    order = np.argsort(given.t, kind="stable")
    first = np.concatenate([[True], np.diff(given.t[order]) > 0])
    keep = order[first]
    poses = PoseSeries(given.t[keep] - origin_s, given.p_w_c[keep], given.q_w_c[keep])
    spans = {"estimate": float(np.ptp(poses.t)), "ground-truth": float(np.ptp(gt.t))}
    clocks = clock_unit_problems(
        spans, {"estimate": _name(estimate), "ground-truth": time_source(dataset, "ground-truth")}
    )
    if clocks:
        raise EasVoError(next(iter(clocks.values())))
    return poses, gt


def protocol_score(dataset, estimate: Estimate, duration_s: float | None = None):
    """The rotation benchmark's score (evaluation.rotation_protocol.score) of `estimate` (a TUM
    file or poses in memory) on the opened `dataset`, over `duration_s` [s] (default the
    protocol's 30) from the recording's start as a run counts it: its first frame
    (Dataset.window). Raises EasVoError, naming the file, for what the protocol cannot score."""
    from eas_vo.evaluation import rotation_protocol

    poses, gt = _estimate_and_truth(dataset, estimate, ordered=False)
    times = dataset.frame_times()
    start = float(times[0]) if len(times) else float(gt.t[0])
    try:
        scored = rotation_protocol.score(poses, gt, start, duration_s or rotation_protocol.DURATION_S)
    except ValueError as exc:
        raise EasVoError(f"{_name(estimate)}: {exc}") from None
    if not len(scored.t):
        raise EasVoError(f"{_name(estimate)}: the ground truth scores none of its poses in the window")
    return scored


def evaluate_protocol(
    dataset: str | Dataset, estimate: Estimate, out: str | Path | None = None, replace: bool = False
) -> dict:
    """Score an external trajectory under the event-rotation benchmark's protocol
    (protocol_score: the first 30 s from the recording's first frame) against the ground truth
    of `dataset` (a `--dataset` value or an opened dataset); with `out`, write metrics.json and
    rotation_errors.png. Returns the metrics."""
    from eas_vo.evaluation import rotation_protocol
    from eas_vo.plots import plot_protocol_errors

    dataset = _opened(dataset)
    scored = protocol_score(dataset, estimate)
    metrics = {
        "estimate": _file(estimate),
        "dataset": dataset.label,
        "protocol": rotation_protocol.NAME,
        **scored.summary(),
    }
    if out is not None:
        with output_folder(out, replace) as staging:
            write_text_atomic(staging / "metrics.json", json_text(metrics))
            label = Path(_file(estimate)).name if _file(estimate) else "estimate"
            plot_protocol_errors(staging / "rotation_errors.png", {label: scored}, title=f"{dataset.label}: {label}")
    return metrics


def _coverage(t_est: np.ndarray, t_gt: np.ndarray, summary: dict) -> dict:
    """How much of an estimate (times `t_est` [s]) its ground truth (`t_gt` [s]) scored:
    matched_fraction (matched_poses / estimate poses), the ground truth's first and last time
    from the estimate's first [s] (ground_truth_span_s), the estimate's span [s], and
    `warnings`: one line below evaluation.MIN_SCORED_FRACTION matched."""
    from eas_vo.evaluation.ape import MIN_SCORED_FRACTION

    matched, n = summary["matched_poses"], len(t_est)
    start, end = float(t_gt[0] - t_est[0]), float(t_gt[-1] - t_est[0])
    span = float(t_est[-1] - t_est[0])
    warnings = []
    if matched < MIN_SCORED_FRACTION * n:
        warnings.append(
            f"the ground truth scores only {matched} of the estimate's {n} poses ({100 * matched / n:.0f} %, "
            f"under {100 * MIN_SCORED_FRACTION:.0f} %): it spans {start:.3f} to {end:.3f} s of the estimate's "
            f"0 to {span:.3f} s; the APE describes those poses only"
        )
    return {
        "matched_fraction": matched / n,
        "ground_truth_span_s": [start, end],
        "estimate_span_s": span,
        "warnings": warnings,
    }


def table2_row(label: str, metrics: dict) -> str:
    """A Markdown row as in the paper's Table 2: source, average (translation) APE [m], with
    RMSE, rotation APE, scale and matched poses beside it."""
    m = metrics
    return (
        "| source | average APE [m] | RMSE [m] | rotation APE [rad] | scale | poses |\n|---|---|---|---|---|---|\n"
        f"| {markdown_cell(label)} | {figure_text(m['ape_trans_mean_m'], 3)} | {figure_text(m['ape_trans_rmse_m'], 3)} | "
        f"{m['ape_rot_mean_rad']:.3f} | "
        f"{m['scale']:.3g} | {m['matched_poses']} |\n"
    )
