"""`eas-vo convert`: any recording eas-vo reads, written in the Event Camera Dataset layout."""

from __future__ import annotations

import sys

from eas_vo.cli.options import (
    add_config,
    add_dataset,
    add_lenient,
    add_output_options,
    add_quiet,
    add_window,
    dataset_inputs,
    refuse_inputs_inside,
    set_assignments,
    shows_progress,
    window_overrides,
)


def add_parser(sub) -> None:
    """`eas-vo convert`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "convert",
        help="write any readable sequence (or a window of it) as an Event Camera Dataset folder",
        description="Read a dataset through its plugin and write it in the Event Camera Dataset text layout: "
        "images/ and images.txt (the APS frames, as PNG; none for an event-only stream), events.txt, imu.txt "
        "and groundtruth.txt (when it has them) and calib.txt. With --start/--duration, the frames of that "
        "window, the events from the frame before it to the frame after it, and the IMU readings and poses "
        "over that span and one more at each end. The folder is written whole, or not at all.",
        epilog="then, e.g.: eas-vo run --dataset OUT --config paper",
    )
    add_dataset(parser)
    add_config(
        parser,
        config_help="config file for the dataset's settings (its [dataset] table)",
        set_help="override one dataset setting, e.g. dataset.sample_rate_hz=100 (repeatable)",
    )
    add_window(parser)
    add_quiet(parser)
    add_lenient(parser)
    add_output_options(parser, required=True)
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo convert` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.io.outputs import check_output_folder
    from eas_vo.sequence.convert import convert

    config = config_mod.resolve(args.config, {"dataset": args.dataset, **window_overrides(args)}, set_assignments(args))
    out = check_output_folder(args.out, replace=args.overwrite)
    refuse_inputs_inside(out, dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config))
    done = convert(config, out, progress=shows_progress(args), replace=args.overwrite)
    for line in done.warnings:
        print(f"eas-vo: warning: {line}", file=sys.stderr)
    print(
        f"wrote {done.frames} frames, {done.events} events, {done.imu} IMU readings and {done.poses} poses of "
        f"{done.label} ({done.span_s:.3f} s) as an Event Camera Dataset folder to {out}"
    )
    if not done.frames:
        width, height = done.sensor
        print(
            f"  an event-only stream: open it with --set dataset.width={width} --set dataset.height={height} "
            "(without frames, its sensor size is not in the folder)"
        )
    return 0
