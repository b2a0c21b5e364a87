"""A trajectory another tool wrote (ORB-SLAM's, CMax-SLAM's, any TUM file) scored against a
dataset's ground truth as evo_ape scores it, and its row of the paper's Table 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eas_vo.errors import EasVoError
from eas_vo.io.atomic import json_text, write_text_atomic
from eas_vo.io.outputs import output_folder
from eas_vo.io.text import figure_text, markdown_cell
from eas_vo.types import PoseSeries


def evaluate_estimate(
    dataset_spec: str,
    estimate_path: str | Path,
    align: str,
    max_diff_s: float,
    out: str | Path | None = None,
    label: str | None = None,
    replace: bool = False,
) -> dict:
    """Score an external trajectory against a dataset's ground truth (evaluation.trajectory_ape);
    with `out`, write metrics.json, table2_row.md, groundtruth.tum (what it was compared with)
    and estimate_aligned.tum. Returns the metrics."""
    from eas_vo.evaluation.trajectory import ALIGNMENTS, trajectory_ape
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum
    from eas_vo.registry import open_dataset

    if align not in ALIGNMENTS:
        raise EasVoError(f"--align {align!r}: choose one of {', '.join(ALIGNMENTS)}")
    dataset = open_dataset(dataset_spec)
    estimate, gt = _estimate_and_truth(dataset, estimate_path)
    origin_ns = dataset.clock_origin_ns
    try:
        ape = trajectory_ape(gt, estimate, align, max_diff_s)
    except ValueError as exc:
        raise EasVoError(f"{estimate_path}: {exc}") from None
    label = label or Path(estimate_path).stem
    metrics = {
        "estimate": str(estimate_path),
        "dataset": dataset.label,
        "align": align,
        "max_diff_s": max_diff_s,
        "estimate_poses": len(estimate.t),
        **ape.summary(),
        **_coverage(estimate.t, gt.t, ape.summary()),
    }
    if out is not None:
        with output_folder(out, replace) as staging:
            write_text_atomic(staging / "metrics.json", json_text(metrics))
            write_text_atomic(staging / "table2_row.md", table2_row(label, metrics))
            write_text_atomic(
                staging / "groundtruth.tum", format_tum(gt.t, gt.p_w_c, matrices_from_quats(gt.q_w_c), origin_ns)
            )
            aligned = ape.aligned(estimate.p_w_c, matrices_from_quats(estimate.q_w_c))
            write_text_atomic(staging / "estimate_aligned.tum", format_tum(estimate.t, *aligned, origin_ns))
    return metrics


def _estimate_and_truth(dataset, estimate_path: str | Path, ordered: bool = True):
    """(the estimate on the dataset's clock [s], its ground truth): the TUM file holds the
    recording's own times, the ground truth is read after its clock origin. `ordered` False
    takes the poses sorted by time, the first of any repeated time (a frame skipped as the
    same image as the previous keeps its pose). Raises EasVoError for a dataset without ground
    truth or an estimate in another clock unit."""
    from eas_vo.datasets.recording import clock_unit_problems, time_source
    from eas_vo.io.tum import read_tum

    gt = dataset.ground_truth
    if gt is None:
        raise EasVoError(f"{dataset.label}: has no ground truth to evaluate against")
    read = read_tum(estimate_path, ordered=ordered)
    order = np.argsort(read.t, kind="stable")
    first = np.concatenate([[True], np.diff(read.t[order]) > 0])
    keep = order[first]
    estimate = PoseSeries(read.t[keep] - dataset.clock_origin_ns / 1e9, read.p_w_c[keep], read.q_w_c[keep])
    spans = {"estimate": float(np.ptp(estimate.t)), "ground-truth": float(np.ptp(gt.t))}
    clocks = clock_unit_problems(
        spans, {"estimate": str(estimate_path), "ground-truth": time_source(dataset, "ground-truth")}
    )
    if clocks:
        raise EasVoError(next(iter(clocks.values())))
    return estimate, gt


def protocol_score(dataset, estimate_path: str | Path, duration_s: float | None = None):
    """The rotation benchmark's score (evaluation.rotation_protocol.score) of the TUM file
    `estimate_path` on the opened `dataset`, over `duration_s` [s] (default the protocol's 30)
    from the recording's start as a run counts it: its first frame (Dataset.window). Raises
    EasVoError, naming the file, for what the protocol cannot score."""
    from eas_vo.evaluation import rotation_protocol

    estimate, gt = _estimate_and_truth(dataset, estimate_path, ordered=False)
    times = dataset.frame_times()
    start = float(times[0]) if len(times) else float(gt.t[0])
    try:
        scored = rotation_protocol.score(estimate, gt, start, duration_s or rotation_protocol.DURATION_S)
    except ValueError as exc:
        raise EasVoError(f"{estimate_path}: {exc}") from None
    if not len(scored.t):
        raise EasVoError(f"{estimate_path}: the ground truth scores none of its poses in the window")
    return scored


def evaluate_protocol(
    dataset_spec: str, estimate_path: str | Path, out: str | Path | None = None, replace: bool = False
) -> dict:
    """Score an external trajectory under the event-rotation benchmark's protocol
    (protocol_score: the first 30 s from the recording's first frame); with `out`, write
    metrics.json and rotation_errors.png. Returns the metrics."""
    from eas_vo.evaluation import rotation_protocol
    from eas_vo.plots import plot_protocol_errors
    from eas_vo.registry import open_dataset

    dataset = open_dataset(dataset_spec)
    scored = protocol_score(dataset, estimate_path)
    metrics = {
        "estimate": str(estimate_path),
        "dataset": dataset.label,
        "protocol": rotation_protocol.NAME,
        **scored.summary(),
    }
    if out is not None:
        with output_folder(out, replace) as staging:
            write_text_atomic(staging / "metrics.json", json_text(metrics))
            label = Path(estimate_path).name
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
