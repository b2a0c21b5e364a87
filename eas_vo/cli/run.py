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
from eas_vo.cli.view import add_spawn, write_and_say

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
  run.rrd          with --view: the run's Rerun recording (eas-vo view)

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
    parser.add_argument(
        "--view", action="store_true", help="after the run, write its Rerun recording run.rrd into --out (eas-vo view)"
    )
    add_spawn(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo run` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo import pipeline
    from eas_vo.io.outputs import check_output_folder
    from eas_vo.io.text import slug

    apply_threads(args)
    viewed = args.view or args.spawn
    if viewed:
        from eas_vo.io.rerun_log import rerun_sdk

        rerun_sdk()  # before the run: one line if it is missing
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
    print(f"{summary_line(rc, m)} -> {out}")
    if viewed:
        write_and_say(out, args.spawn)
    return 0


def summary_line(rc, m: dict) -> str:
    """The run's one line (about 160 characters): plugins and dataset, frames by status, the
    average number of correspondences (NC; for trackers that read images), the average APE, and
    what applies to this run only (frames the ground truth missed, an estimated time offset,
    loops closed, the gyro's verdict where something read it); `m` is metrics.json's content, `rc` the [run] section."""
    from eas_vo import registry

    counts = m["status_counts"]
    parts = [
        f"{rc.frontend}+{rc.tracker}+{rc.backend} on {rc.dataset}: {m['frames']} frames ("
        + ", ".join(f"{counts[s]} {s}" for s in ("ok", "weak", "lost", "same_time") if counts.get(s))
        + ")"
    ]
    if registry.get("trackers", rc.tracker).reads_images:
        parts.append(f"average NC {m['nc_mean']:.1f}")
    ape = m.get("ape_mean_rad")
    if "frames_scored_fraction" not in m:
        parts.append("no ground truth")
    elif not m["frames_evaluated"]:
        parts.append("no frame scored")
    else:
        scored = "" if m["frames_evaluated"] == m["frames"] else f"; {m['frames_evaluated']} of {m['frames']} frames"
        parts.append(f"average APE {ape:.4f} rad ({ape * 57.29577951:.2f} deg{scored})")
    if m["time_offset_estimated"]:
        parts.append(
            f"time offset {m['time_offset_s'] * 1e3:+.1f} ms (estimated on the ground truth it scores against)"
        )
    if m["loop_count"] is not None:  # the tracker looks for loops
        parts.append(f"{m['loop_count']} loop(s) closed")
    if m["gyro_use"]:  # something read the gyro: the images' verdict on it
        parts.append(f"gyro {m['gyro']}")
    parts.append(f"{m['frames_per_s']:.1f} frames/s")
    return ", ".join(parts)
