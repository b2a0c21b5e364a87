"""`eas-vo info`: what a recording holds, before any long work."""

from __future__ import annotations

from eas_vo.cli.options import add_config, add_dataset, add_lenient, set_assignments


def add_parser(sub) -> None:
    """`eas-vo info`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "info",
        help="say what a recording holds (streams, sensor, camera, spans, rates) before any long work",
        description="Open a dataset through its plugin and print the streams it holds (frames, events, IMU, ground "
        "truth), the sensor size, the camera model and intrinsics, and each stream's span, count and rate. "
        "Reads the frame list and at most one frame, and the event stream once (a text reader caches it for later runs).",
    )
    add_dataset(parser)
    add_config(
        parser,
        config_help="config file for the dataset's settings (its [dataset] table)",
        set_help="override one dataset setting, e.g. dataset.sample_rate_hz=100 (repeatable)",
    )
    add_lenient(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo info` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.sequence.info import describe

    config = config_mod.resolve(args.config, {"dataset": args.dataset}, set_assignments(args))
    print("\n".join(describe(config).lines()))
    return 0
