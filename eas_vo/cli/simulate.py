"""`eas-vo simulate`: a synthetic dim-scene DAVIS sequence in the ECD layout."""

from __future__ import annotations

import sys

from eas_vo.cli.options import add_output_options
from eas_vo.errors import UsageError


def add_parser(sub) -> None:
    """`eas-vo simulate`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "simulate",
        help="write a synthetic dim-scene DAVIS sequence (ECD layout)",
        description="Simulate a textured HDR room seen by a hand-held DAVIS240 (or another camera: "
        "--set dataset.sensor=davis346, dataset.width=W dataset.height=H, dataset.lens=equidistant "
        "dataset.dist=[k1,k2,k3,k4]): APS frames, events, ground truth (200 Hz), IMU (200 Hz) and the "
        "calibration (calib.txt; camchain.yaml, kalibr's, for a fisheye) in the Event Camera Dataset text layout.",
    )
    add_output_options(parser, required=True)
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--duration", type=float, default=10.0, metavar="S", help="length in seconds (default 10)")
    parser.add_argument(
        "--illumination",
        type=float,
        metavar="X",
        help="scale of the scene's light (default 1.0, the dim room; 0.1 is ten times darker)",
    )
    parser.add_argument(
        "--speed",
        type=float,
        metavar="X",
        help="scale of the camera's speed (default 1.0, hand-held: 44 deg/s mean; 4 gives 177 deg/s, "
        "more than the real shapes_rotation's 147): the same path, travelled X times as fast",
    )
    parser.add_argument(
        "--set",
        dest="assignments",
        action="append",
        default=[],
        metavar="dataset.KEY=VALUE",
        help="a camera or DVS pixel value, as for run (see `eas-vo list`: the synthetic dataset's keys)",
    )
    parser.add_argument(
        "--stats",
        action="store_true",
        help="print what the simulator knows of its events: rate, noise fraction, noise rate "
        "per pixel and median latency in dark and bright regions",
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo simulate` on the parsed `args`; returns the exit status."""
    from eas_vo.config import build, parse_set
    from eas_vo.datasets.simulator import SimConfig, simulate
    from eas_vo.datasets.synthetic import SyntheticConfig
    from eas_vo.io.outputs import check_output_folder, output_folder

    pixel = {}
    for assignment in args.assignments:
        keys, value = parse_set(assignment)
        if keys[0] != "dataset" or len(keys) != 2:
            raise UsageError(f"--set {assignment!r}: simulate takes dataset.KEY=VALUE (the synthetic dataset's keys)")
        pixel[keys[1]] = value
    flags = {
        key: value for key, value in (("illumination", args.illumination), ("speed", args.speed)) if value is not None
    }
    for key in sorted(flags.keys() & pixel.keys()):
        raise UsageError(f"--{key} and --set dataset.{key} both given: give one")
    if "duration_s" in pixel:
        raise UsageError("--set dataset.duration_s: simulate's length is --duration")
    sensor = build(SyntheticConfig, {**pixel, **flags}, "dataset")
    config = sensor.applied_to(build(SimConfig, {"seed": args.seed, "duration_s": args.duration}, "simulate"))
    check_output_folder(args.out, replace=args.overwrite)
    with output_folder(args.out, replace=args.overwrite, keep_partial=False) as staging:  # whole, or not at all
        stats = simulate(config, staging, progress=sys.stderr.isatty())
    cam = config.camera
    print(
        f"wrote a {config.duration_s:g} s synthetic sequence (seed {config.seed}, illumination {config.illumination:g}, "
        f"speed {config.speed:g}, {cam.width}x{cam.height} {cam.lens}) to {args.out}"
    )
    if args.stats:
        print("\n".join("  " + line for line in stats.lines()))
    return 0
