"""`eas-vo render`: every frontend's image of chosen frames side by side."""

from __future__ import annotations

from eas_vo.cli.options import add_config, add_dataset, dataset_inputs, refuse_inputs_inside
from eas_vo.errors import UsageError


def add_parser(sub) -> None:
    """`eas-vo render`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "render",
        help="draw every frontend's image of chosen frames side by side (like the paper's Fig. 1)",
        description="Run every frontend (or --frontends) over a dataset up to the chosen frames and "
        "draw their images in a grid: one row per frame, one column per frontend.",
    )
    add_dataset(parser)
    parser.add_argument("--frames", required=True, metavar="I,J,...", help="frame indices, e.g. 20,120")
    parser.add_argument(
        "--frontends", metavar="A,B,...", help="frontends to show (default: every installed one that makes an image)"
    )
    add_config(
        parser,
        config_help="config file for the frontends' settings",
        set_help="override one config value, e.g. frontend.n=8000 (repeatable)",
    )
    parser.add_argument("--out", required=True, metavar="PNG", help="output image, e.g. gallery.png")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing --out if it is a PNG image (never one of the inputs)",
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo render` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.experiments.gallery import frontend_images
    from eas_vo.io.atomic import atomic_path
    from eas_vo.io.outputs import check_output_file, refuse_foreign_file
    from eas_vo.plots import plot_gallery

    out = check_output_file(args.out, replace=args.overwrite)
    try:
        frames = [int(v) for v in args.frames.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"--frames takes comma-separated frame indices, got {args.frames!r}") from None
    if not frames:
        raise UsageError("--frames names no frame")
    config = config_mod.resolve(args.config, {"dataset": args.dataset}, args.assignments)
    dataset = config.run.dataset
    refuse_inputs_inside(out, dataset_inputs(dataset, config.dataset), ("the --config", args.config), out_is_file=True)
    refuse_foreign_file(out, "PNG image")
    frontends = [v.strip() for v in args.frontends.split(",")] if args.frontends else None
    names, images = frontend_images(args.dataset, frames, frontends, args.config, args.assignments)
    with atomic_path(out) as tmp:
        plot_gallery(tmp, names, images, frames, title=dataset)
    print(f"wrote {len(frames)} frame(s) x {len(names)} frontend(s) to {out}")
    return 0
