"""Calibrates the per-frame status (ok / weak) on data with ground truth (docs/frame_status.md).

Every frame-to-frame measurement R_{k-1}_{k} of a run is compared with the ground truth's
relative rotation between the two frame times (camera frame, the run's ground-truth time
offset): `right` where the angle of R_est^T R_gt, times the focal length, is below
RIGHT_PX, `wrong` above WRONG_PX, between the two neither. The signal is the error the
measurement's own covariance predicts: its largest 1-sigma times the focal length [px of focal
length] (measurement.predicted_error_px); beside it the status the tracker decided with
(measurement.weakness and StepBound: inliers, inlier ratio, residual, the motion before),
which steers its fallbacks and is what runs reported before the status read the covariance.

The bound (TwoViewConfig.max_predicted_error_px) is chosen on the paper configuration's runs
on the choice data (`synthetic:default` and the real excerpt's first 20 s): among the bounds of
GRID that call at most MAX_RIGHT_WEAK of the right measurements weak, the one that calls the
fewest wrong ones ok (each share the mean over the runs, so that no run outweighs the others by
its length; ties to the fewest frames weak). A frame is weak under a bound B when its step has
fewer than min_inliers inliers, predicts an error above B, or was doubted by StepBound (a rate
the motion before it makes doubtful; --without-bound leaves that reason out). The rates are
then reported on the held-out data (simulator seeds 41-43, the real excerpt's 20-30 s) beside
the status decided by the quality thresholds, for the paper's and best.toml's klt and for match.

    python benchmarks/status_calibration.py [--real DIR | --real ''] [--seeds 41 42 43]
                                            [--only LABEL ...] [--rows FILE] [--from FILE ...]
                                            [--cuts RIGHT,WRONG] [--without-bound]

--rows writes every measurement (one CSV line each); --from reads such files instead of
running (the choice and the tables only); --only runs some of the data (e.g. 'seed 41');
--cuts sets the right and wrong cuts [px of focal length] (a sensitivity check; the defaults
are RIGHT_PX, WRONG_PX). Seeds are simulated once into $EAS_VO_CACHE_DIR/simulated/seed-N
(about 40 s each).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
from select_best import seed_folder
from study import add_real, real_folder

from eas_vo import concurrency, config, pipeline, registry
from eas_vo.geometry.rotations import geodesic_angle, interpolate_poses
from eas_vo.trackers import klt, match, measurement
from eas_vo.trackers.measurement import STEP_BOUND_REASON, predicted_error_px
from eas_vo.types import PoseSeries

#: A measurement is right when its rotation error moves a point by less than this [px] (the
#: error [rad] times the focal length [px]): 0.7 px, 0.2 deg at the DAVIS240's 199 px, is
#: below the 1 px inlier threshold, so the estimate's own inliers would all stay inliers.
RIGHT_PX = 0.7
#: ... and wrong above this [px]: 3.5 px, 1 deg at 199 px, over three inlier thresholds: most
#: correct correspondences would be outliers of the estimated rotation.
WRONG_PX = 3.5
#: The runs: (tracker, bundled config file) and the frontends each runs with; `match` (its
#: defaults) on one frontend per data.
CONFIGS = (("klt", "paper"), ("klt", "best"))
SYNTHETIC_FRONTENDS = ("eas", "histeq", "ts")
REAL_FRONTENDS = ("histeq", "original")  # the real excerpt has events for its first 0.5 s only
MATCH_FRONTEND = "histeq"  # ORB matches one frame in 200 on the dim simulated eas images
REAL_OFFSET_S = 0.01  # the excerpt's frames lead its ground truth by 10 ms (its README)
FIELDS = (
    "data",
    "split",
    "tracker",
    "config",
    "frontend",
    "index",
    "status",
    "reason",
    "decided_status",
    "decided_reason",
    "inliers",
    "min_inliers",
    "inlier_ratio",
    "residual_px",
    "predicted_px",
    "sigma_x_px",
    "sigma_y_px",
    "sigma_z_px",
    "focal_px",
    "gt_angle_deg",
    "error_deg",
)
#: The share of right measurements the chosen bound may call weak (on the choice data): the
#: largest the status is allowed to have on any data.
MAX_RIGHT_WEAK = 0.25
#: The bounds [px of focal length] the choice is made among: 0.05 px apart from 0.1 to 10 px,
#: then 0.5 px apart to 20 px.
GRID = tuple(np.round(np.concatenate([np.arange(0.1, 10.0, 0.05), np.arange(10.0, 20.01, 0.5)]), 2))


class GroundTruth(NamedTuple):
    """The ground truth at each frame of a run (ground_truth): NaN where it does not cover the frame."""

    R_w_c: np.ndarray  # (N, 3, 3): R_w_c[i].T @ R_w_c[j] is the true R_i_j
    p_w_c: np.ndarray  # (N, 3) [m]
    focal_px: float  # the camera's focal length [px]
    poses: PoseSeries  # the dataset's ground truth, as recorded
    times: np.ndarray  # (N,) the times it was sampled at [s] (frame times plus the offset)


def ground_truth(cfg, result) -> GroundTruth:
    """The ground truth at each frame of a run's `result`, sampled at frame time plus the run's
    time offset (`run.time_offset_s`: 0 for the simulator, REAL_OFFSET_S for the real excerpt)."""
    gt = registry.open_dataset(cfg.run.dataset, cfg.dataset)
    valid, R_w_c_gt, p_w_c_gt = interpolate_poses(gt.ground_truth, result.t + cfg.run.time_offset_s)
    R_gt, p_gt = np.full((len(result.t), 3, 3), np.nan), np.full((len(result.t), 3), np.nan)
    R_gt[valid], p_gt[valid] = R_w_c_gt, p_w_c_gt
    return GroundTruth(R_gt, p_gt, gt.camera.focal_px, gt.ground_truth, result.t + cfg.run.time_offset_s)


def columns(real: str, seeds: list[int]) -> dict:
    """{label: (split, dataset, frontends, run settings)}."""
    found = {"synthetic:default": ("choice", "synthetic:default", SYNTHETIC_FRONTENDS, {})}
    found.update({f"seed {n}": ("held-out", str(seed_folder(n)), SYNTHETIC_FRONTENDS, {}) for n in seeds})
    if real and Path(real).is_dir():
        for label, split, (start, duration) in (
            ("real 0-20 s", "choice", (0.0, 20.0)),
            ("real 20-30 s", "held-out", (20.0, 10.0)),
        ):
            found[label] = (
                split,
                real,
                REAL_FRONTENDS,
                {"start_s": start, "duration_s": duration, "time_offset_s": REAL_OFFSET_S},
            )
    elif real:
        print(f"{real}: not found, real data skipped", file=sys.stderr)
    return found


def watch_decisions() -> dict:
    """{frame index: (status, reason)} as the tracker decided them, before the status it reports
    (measurement.status) replaced them: filled by every klt and match frame from now on."""
    decided = {}
    reported = measurement.status

    def watched(config, record, step, focal_px):
        decided[record.index] = (record.status, record.reason)
        return reported(config, record, step, focal_px)

    klt.status = match.status = watched
    return decided


def measurements(
    decided: dict, label: str, split: str, dataset: str, tracker: str, file: str, frontend: str, extra: dict
) -> list[dict]:
    """One row per frame after the first of a run: its record and, where a frame-to-frame
    rotation was measured and ground truth covers both frames, its error [deg]."""
    cfg = config.resolve(file, {"dataset": dataset, "frontend": frontend, "tracker": tracker, **extra})
    decided.clear()
    result = pipeline.run(cfg)
    R_gt, _, focal_px, _, _ = ground_truth(cfg, result)
    valid = np.isfinite(R_gt[:, 0, 0])
    steps = {e.j: e for e in result.edges if e.j == e.i + 1 and not e.loop}
    rows = []
    for r in result.records[1:]:
        status, reason = decided.get(r.index, (r.status, r.reason))
        if r.status == "lost":  # the run's own verdict (e.g. the same image as before) stands
            status, reason = r.status, r.reason
        step = steps.get(r.index)
        row = {
            "data": label,
            "split": split,
            "tracker": tracker,
            "config": file,
            "frontend": frontend,
            "index": r.index,
            "status": r.status,
            "reason": r.reason.split(" (")[0],
            "decided_status": status,
            "decided_reason": reason.split(" (")[0],
            "inliers": r.inliers,
            "min_inliers": cfg.tracker.min_inliers,
            "inlier_ratio": r.inlier_ratio,
            "residual_px": r.residual_px,
            "predicted_px": predicted_error_px(step, focal_px) if step is not None else np.nan,
            **{
                f"sigma_{a}_px": step.sigmas_rad()[n] * focal_px if step is not None else np.nan
                for n, a in enumerate("xyz")
            },
            "focal_px": focal_px,
            "gt_angle_deg": np.nan,
            "error_deg": np.nan,
        }
        if valid[r.index - 1] and valid[r.index]:
            R_gt_ij = R_gt[r.index - 1].T @ R_gt[r.index]
            row["gt_angle_deg"] = float(np.degrees(geodesic_angle(np.eye(3), R_gt_ij)))
            if step is not None:
                row["error_deg"] = float(np.degrees(geodesic_angle(step.R_i_j, R_gt_ij)))
        rows.append(row)
    return rows


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for key in ("inliers", "index", "min_inliers"):
            row[key] = int(row[key])
        for key in FIELDS[FIELDS.index("inlier_ratio") :]:
            row[key] = float(row[key])
    return rows


class Table:
    """The measured rows as arrays: their run, class (right / wrong / neither) and quantities."""

    def __init__(self, rows: list[dict], right_px: float = RIGHT_PX, wrong_px: float = WRONG_PX):
        measured = [r for r in rows if r["status"] in ("ok", "weak") and np.isfinite(r["error_deg"])]
        self.rows = measured
        self.run = np.array([f"{r['data']}|{r['tracker']}|{r['config']}|{r['frontend']}" for r in measured])
        self.split = np.array([r["split"] for r in measured])
        self.config = np.array([f"{r['tracker']} {r['config']}" for r in measured])
        self.real = np.array([r["data"].startswith("real") for r in measured], dtype=bool)
        self.error_px = np.radians([r["error_deg"] for r in measured]) * np.array([r["focal_px"] for r in measured])
        self.right = self.error_px < right_px
        self.wrong = self.error_px > wrong_px
        self.inliers = np.array([r["inliers"] for r in measured])
        self.few = self.inliers < np.array([r["min_inliers"] for r in measured])
        self.predicted = np.array([r["predicted_px"] for r in measured])
        self.pan_tilt = np.array([max(r.get("sigma_x_px", np.nan), r.get("sigma_y_px", np.nan)) for r in measured])
        self.reported_weak = np.array([r["status"] == "weak" for r in measured], dtype=bool)
        self.decided_weak = np.array([r["decided_status"] == "weak" for r in measured], dtype=bool)
        self.bound = np.array([r["decided_reason"].endswith(STEP_BOUND_REASON) for r in measured], dtype=bool)
        self.ratio = np.array([r["inlier_ratio"] for r in measured])
        self.residual = np.array([r["residual_px"] for r in measured])

    def weak(self, bound_px: float, step_bound: bool = True, signal: np.ndarray | None = None) -> np.ndarray:
        """Whether each measurement is weak with this bound on its predicted error [px] (as
        measurement.status; `step_bound`: also where StepBound doubted it; `signal`: another
        predicted error than the largest sigma)."""
        signal = self.predicted if signal is None else signal
        return self.few | ~(signal <= bound_px) | (self.bound & step_bound)

    def rates(self, weak: np.ndarray, use: np.ndarray) -> tuple[float, float]:
        """(right called weak, wrong called ok): each the mean over the runs in `use` that have
        such measurements."""
        runs = np.unique(self.run[use])
        right_weak = [
            weak[use & self.right & (self.run == u)].mean() for u in runs if (use & self.right & (self.run == u)).any()
        ]
        wrong_ok = [
            (~weak[use & self.wrong & (self.run == u)]).mean()
            for u in runs
            if (use & self.wrong & (self.run == u)).any()
        ]
        return (float(np.mean(right_weak)) if right_weak else np.nan, float(np.mean(wrong_ok)) if wrong_ok else np.nan)


def choose(
    table: Table, step_bound: bool, signal: np.ndarray | None = None
) -> tuple[float, tuple[float, float]] | None:
    """The bound of GRID for the paper's configuration: on its runs on the choice data, among
    those calling at most MAX_RIGHT_WEAK of the right measurements weak, the one calling the
    fewest wrong ones ok; ties to the fewest frames weak. None where no bound qualifies."""
    use = (table.split == "choice") & (table.config == "klt paper")
    best = None
    for bound in GRID:
        weak = table.weak(bound, step_bound, signal)
        rates = table.rates(weak, use)
        if not rates[0] <= MAX_RIGHT_WEAK:
            continue
        key = (round(rates[1], 6), int(weak[use].sum()))
        if best is None or key < best[0]:
            best = (key, bound, rates)
    return None if best is None else (best[1], best[2])


def percentiles(values: np.ndarray) -> str:
    return " / ".join(f"{v:.2f}" for v in np.percentile(values, (5, 50, 95))) if len(values) else "-"


def report(table: Table, bound: float, step_bound: bool) -> None:
    print("\n## What the measurements look like (5th / 50th / 95th percentile)\n")
    print(
        "| data | tracker | config | frontend | right | wrong | neither | predicted right [px] | predicted wrong [px] | inliers right | inliers wrong |"
    )
    print("|---" * 11 + "|")
    for u in dict.fromkeys(table.run):
        m = table.run == u
        r, w = m & table.right, m & table.wrong
        print(
            f"| {' | '.join(u.split('|'))} | {r.sum()} | {w.sum()} | {(m & ~table.right & ~table.wrong).sum()} | "
            f"{percentiles(table.predicted[r])} | {percentiles(table.predicted[w])} | "
            f"{percentiles(table.inliers[r])} | {percentiles(table.inliers[w])} |"
        )
    print("\n## Rates (mean over the runs): right measurements called weak, wrong ones called ok\n")
    print("| config | status | data | right called weak | wrong called ok | all measurements weak |")
    print("|---|---|---|---|---|---|")
    rules = [
        ("before: quality thresholds and StepBound", table.decided_weak),
        (
            f"after: predicted error > {bound:g} px or few inliers" + (", or StepBound" * step_bound),
            table.weak(bound, step_bound),
        ),
        (f"after, {'without' if step_bound else 'with'} StepBound", table.weak(bound, not step_bound)),
    ]
    pan_tilt = choose(table, step_bound, table.pan_tilt)  # a signal not adopted: what the roll's sigma hides
    if pan_tilt is not None:
        rules.append(
            (f"pan/tilt sigma > {pan_tilt[0]:g} px or few inliers", table.weak(pan_tilt[0], step_bound, table.pan_tilt))
        )
    for file in dict.fromkeys(table.config):
        for (name, weak), split, (kind, real) in itertools.product(
            rules, ("choice", "held-out"), (("all", None), ("synthetic", False), ("real", True))
        ):
            keep = (
                (table.config == file) & (table.split == split) & ((table.real == real) if real is not None else True)
            )
            if keep.any():
                right_weak, wrong_ok = table.rates(weak, keep)
                print(
                    f"| {file} | {name} | {split}, {kind} | {right_weak:.1%} | {wrong_ok:.1%} | {weak[keep].mean():.1%} |"
                )
    print("\n## StepBound's doubted steps (every run)\n")
    use = table.bound
    print(
        f"{use.sum()} doubted: {(use & table.right).sum()} right, {(use & table.wrong).sum()} wrong; "
        f"{(use & ~table.weak(bound, False)).sum()} of them within the bound"
    )
    agree = table.reported_weak == table.weak(bound, step_bound)
    print(f"the status the runs reported is this rule's for {agree.mean():.2%} of the measurements")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser, "the real recording ('' to leave it out)")
    parser.add_argument("--seeds", type=int, nargs="*", default=[41, 42, 43], help="held-out simulator seeds")
    parser.add_argument("--only", nargs="*", metavar="LABEL", help="run only these data (e.g. 'seed 41' 'real 0-20 s')")
    parser.add_argument("--rows", type=Path, help="write every measurement to this CSV file")
    parser.add_argument(
        "--from",
        dest="sources",
        type=Path,
        nargs="*",
        help="read the measurements from these CSV files instead of running",
    )
    parser.add_argument("--cuts", default=f"{RIGHT_PX},{WRONG_PX}", help="right,wrong cuts [px of focal length]")
    parser.add_argument(
        "--without-bound", action="store_true", help="StepBound's doubt is no reason for weak (the chosen rule: it is)"
    )
    parser.add_argument("--threads", type=int, default=1, help="eas-vo's threads (default 1)")
    args = parser.parse_args()
    real = str(real_folder(args.real)) if args.real else ""
    concurrency.set_threads(args.threads)
    right_px, wrong_px = (float(v) for v in args.cuts.split(","))
    if args.sources:
        rows = [row for source in args.sources for row in read_rows(source)]
    else:
        rows, decided = [], watch_decisions()
        seeds = [n for n in args.seeds if not args.only or f"seed {n}" in args.only]  # simulated only where needed
        for label, (split, dataset, frontends, extra) in columns(real, seeds).items():
            if args.only and label not in args.only:
                continue
            runs = [(tracker, file, frontend) for (tracker, file), frontend in itertools.product(CONFIGS, frontends)]
            for tracker, file, frontend in runs + [("match", "paper", MATCH_FRONTEND)]:
                rows += measurements(decided, label, split, dataset, tracker, file, frontend, extra)
                print(f"{label} {tracker} {file} {frontend}: {len(rows)} rows", file=sys.stderr, flush=True)
        if args.rows:
            with open(args.rows, "w", newline="") as f:
                writer = csv.DictWriter(f, FIELDS)
                writer.writeheader()
                writer.writerows(rows)
    table = Table(rows, right_px, wrong_px)
    print(
        f"right: error below {right_px} px of focal length, wrong: above {wrong_px} px; {len(table.rows)} measurements"
    )
    chosen = choose(table, not args.without_bound)
    if chosen is None:
        print(f"no bound calls at most {MAX_RIGHT_WEAK:.0%} of the right measurements weak: the largest reported")
        bound = GRID[-1]
    else:
        bound, (right_weak, wrong_ok) = chosen
        print(
            f"chosen on the choice data: max_predicted_error_px {bound:g} "
            f"(right called weak {right_weak:.1%}, wrong called ok {wrong_ok:.1%})"
        )
    report(table, bound, not args.without_bound)


if __name__ == "__main__":
    main()
