"""`eas-vo run`: one frontend + tracker + backend on a dataset, and its summary line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from eas_vo.cli.options import (
    add_config,
    add_dataset,
    add_lenient,
    add_output_options,
    add_quiet,
    add_threads,
    add_time_offset,
    add_window,
    apply_threads,
    dataset_inputs,
    installed_names,
    refuse_inputs_inside,
    set_assignments,
    shared_overrides,
    shows_progress,
)

EPILOG_RUN = """\
outputs (in --out):
  trajectory.tum   estimated camera-to-world rotation per frame (TUM: t tx ty tz qx qy qz qw)
  groundtruth.tum  ground truth at the same timestamps (when the dataset has it)
  metrics.json     average APE (Eq. 3, rad), RMSE, max, average NC, frames, timing
  frames.csv       per frame: index, t, NC, inliers, status (first, ok, weak, lost, same_time), redetected,
                   inlier ratio, residual [px], why the frame is weak or lost, its step's sigmas [deg]
  orientation_sigma.csv
                   per frame: its orientation's 1-sigma [deg] about each camera axis, the chain's
                   propagated and the backend's
  config.toml      the resolved configuration (re-run with --config config.toml)
  rotation.png     estimated (+-1 sigma) and true roll/pitch/yaw over time

examples:
  eas-vo run --frontend eas --backend chain
  eas-vo run --dataset path/to/hdr_boxes --frontend original --start 0 --duration 25
  eas-vo run --frontend eas --set frontend.n=8000 --set tracker.threshold1=15
  eas-vo run --dataset ecd:path/to/folder --tracker klt --config best
"""


def add_parser(sub) -> None:
    """`eas-vo run`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "run",
        help="estimate rotation on a sequence and evaluate it",
        description="Run one frontend + tracker + backend on a dataset and write the trajectory, metrics and plots.",
        epilog=EPILOG_RUN,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from eas_vo.config import RunConfig

    add_dataset(
        parser,
        help=f"a recording (a folder or file) one of the installed dataset plugins opens, or "
        f"PLUGIN:LOCATION, PLUGIN one of {installed_names('datasets')}; synthetic:NAME is simulated once "
        f"(default {RunConfig.dataset}; eas-vo list says what each plugin reads)",
    )
    parser.add_argument(
        "--frontend",
        metavar="NAME",
        help=f"image source, one of {installed_names('frontends')} (default {RunConfig.frontend})",
    )
    parser.add_argument(
        "--tracker",
        metavar="NAME",
        help=f"relative rotations between frames, one of {installed_names('trackers')} "
        f"(default {RunConfig.tracker}, the paper's)",
    )
    parser.add_argument(
        "--backend",
        metavar="NAME",
        help=f"relative -> absolute rotations, one of {installed_names('backends')} (default {RunConfig.backend})",
    )
    add_config(parser)
    add_window(parser)
    add_time_offset(parser)
    add_quiet(parser)
    add_lenient(parser)
    add_threads(parser)
    add_output_options(parser, required=False, default="runs/DATASET_FRONTEND_TRACKER_BACKEND_TIME")
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo run` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo import pipeline
    from eas_vo.io.outputs import check_output_folder
    from eas_vo.io.text import slug

    apply_threads(args)
    config = config_mod.resolve(
        args.config,
        {
            "dataset": args.dataset,
            "frontend": args.frontend,
            "tracker": args.tracker,
            "backend": args.backend,
            **shared_overrides(args),
        },
        set_assignments(args),
    )
    rc = config.run
    if args.out:
        out = check_output_folder(args.out, replace=args.overwrite)
        refuse_inputs_inside(out, dataset_inputs(rc.dataset, config.dataset), ("the --config", args.config))
    else:
        import time

        out = Path(f"runs/{slug(rc.dataset)}_{rc.frontend}_{rc.tracker}_{rc.backend}_{time.strftime('%Y%m%d-%H%M%S')}")
    result = pipeline.run(config, out, progress=shows_progress(args), replace=args.overwrite)
    m = result.metrics
    for line in m["data_warnings"]:
        print(f"eas-vo: warning: {line}", file=sys.stderr)
    ape = m.get("ape_mean_rad")
    ape_text = "no ground truth"
    if "frames_scored_fraction" in m:  # scored: over how many frames and what span of the run
        start, end = m["ground_truth_span_s"]
        scored = f"{m['frames_evaluated']} of {m['frames']} frames scored, ground truth from {start:.3f} to {end:.3f} s of the run's 0 to {m['sequence_s']:.3f} s"
        ape_text = (
            f"average APE {ape:.4f} rad ({ape * 57.29577951:.2f} deg; {scored})"
            if m["frames_evaluated"]
            else f"no frame scored ({scored})"
        )
    if m["time_offset_estimated"]:
        ape_text += (
            f" (time offset {m['time_offset_s'] * 1e3:+.1f} ms, estimated on the ground truth it scores against)"
        )
    statuses = _status_text(m["status_counts"], m["status_reasons"])
    meaning = f" [{WEAK_MEANS}]" if m["status_counts"].get("weak") else ""
    loops = f"{m['loop_count']} loop(s) closed, " if m["loop_count"] is not None else ""
    gyro = f"gyro {' '.join(filter(None, (m['gyro'], m['gyro_use'])))}, " if m["gyro"] else ""
    print(
        f"{rc.frontend}+{rc.tracker}+{rc.backend} on {rc.dataset}: {m['frames']} frames ({statuses}){meaning}, "
        f"average NC {m['nc_mean']:.1f}, {loops}{gyro}"
        f"{ape_text}, {m['frames_per_s']:.1f} frames/s -> {out}"
    )
    return 0


#: What a weak frame is, after the status counts (docs/frame_status.md has the calibration).
WEAK_MEANS = "weak: less reliable than usual, not necessarily wrong; 19-66 % of frames with the paper's settings"


def _status_text(counts: dict, reasons: dict) -> str:
    """'1 first, 54 ok, 172 weak: 160 predicted error, 12 few inliers' (most frequent reason first)."""
    parts = []
    for status in ("first", "ok", "weak", "lost", "same_time"):
        if counts.get(status):
            why = sorted(reasons.get(status, {}).items(), key=lambda kv: (-kv[1], kv[0]))
            parts.append(f"{counts[status]} {status}" + (": " + ", ".join(f"{n} {r}" for r, n in why) if why else ""))
    return "; ".join(parts) if any(": " in p for p in parts) else ", ".join(parts)
