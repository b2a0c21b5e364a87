"""`eas-vo export`: a frontend's images as a sequence ORB-SLAM2 reads."""

from __future__ import annotations

from eas_vo.cli.options import (
    add_config,
    add_dataset,
    add_output_options,
    add_quiet,
    add_window,
    dataset_inputs,
    refuse_inputs_inside,
    shows_progress,
    window_overrides,
)


def add_parser(sub) -> None:
    """`eas-vo export`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "export",
        help="write a frontend's images as a sequence ORB-SLAM2 reads (TUM or EuRoC layout) with its settings.yaml",
        description="Run a frontend (e.g. original or eas) over a dataset window and write its images in the "
        "layout monocular ORB-SLAM2/ORB-SLAM3 examples read, plus settings.yaml (the dataset's calibration in "
        "ORB-SLAM2's format, its frame rate, ORB-SLAM2's ORB extractor defaults): the paper's §4.3.",
        epilog="then, e.g.: ./Examples/Monocular/mono_tum Vocabulary/ORBvoc.txt OUT/settings.yaml OUT  "
        "(writes KeyFrameTrajectory.txt; score it with eas-vo evaluate)",
    )
    add_dataset(parser)
    parser.add_argument("--frontend", metavar="NAME", help="image source (default eas)")
    parser.add_argument(
        "--format",
        choices=("tum", "euroc"),
        default="tum",
        help="tum: rgb.txt + rgb/T.png (mono_tum); euroc: mav0/cam0/data/T_NS.png + timestamps.txt (mono_euroc)",
    )
    add_config(parser)
    add_window(parser)
    add_quiet(parser)
    add_output_options(parser, required=True)
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo export` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.io.outputs import check_output_folder
    from eas_vo.slam.export import export

    config = config_mod.resolve(
        args.config,
        {"dataset": args.dataset, "frontend": args.frontend, **window_overrides(args)},
        args.assignments,
    )
    out = check_output_folder(args.out, replace=args.overwrite)
    refuse_inputs_inside(out, dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config))
    done = export(config, out, args.format, progress=shows_progress(args), replace=args.overwrite)
    print(
        f"wrote {done['frames']} {done['frontend']} images of {done['dataset']} ({done['format']} layout, "
        f"{done['fps']:.2f} frames/s) and settings.yaml to {out}"
    )
    return 0
