"""`eas-vo reproduce`: the paper's Table 1 or Table 2 on its own data, or the event-rotation benchmark."""

from __future__ import annotations

from eas_vo.cli.options import (
    add_jobs,
    add_quiet,
    dataset_inputs,
    name_list,
    positive_int,
    refuse_inputs_inside,
    report_cells,
    seconds,
    shows_progress,
)
from eas_vo.errors import UsageError


def add_parser(sub) -> None:
    """`eas-vo reproduce`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "reproduce",
        help="the paper's Table 1 or Table 2 on its own data (hdr_boxes, hdr_poster), beside its figures; "
        "or the event-rotation benchmark (ECD's four rotation sequences, CMax-SLAM's protocol)",
        description="table1: fetch hdr_boxes and hdr_poster, run the six sources with --config paper on the first "
        "25 s (time offset estimated) with both backends, and write table1.md (ours beside the paper's, ratios, "
        "orderings), compare's tables and figures, and Fig. 3-style Euler plots. table2: ORB features and matches "
        "of original and EAS images (or --frontends) and the keyframe APE after Sim(3) alignment of monocular SLAM "
        "on them: with the slam extra, --runs runs of ORB-SLAM3 per cell (eas-vo slam; ORBvoc.txt fetched unless "
        "--vocabulary), and for ORB-SLAM2 keyframe trajectories given with --estimate (run it on `eas-vo export` "
        "output), those; table2.md beside the paper's and Fig. 4-style keyframe plots. rotation: fetch "
        "shapes_rotation, poster_rotation, boxes_rotation and dynamic_rotation, run paper.toml, best.toml without "
        "and with the gyro, cmax + chain, cmax + gtsam with the gyro and the gyro alone on the first 30 s, score "
        "them under --protocol and write rotation.md beside CMax-SLAM's published Table III, with a figure per "
        "sequence. Resumable: the same command runs only what is missing.",
    )
    parser.add_argument("table", choices=("table1", "table2", "rotation"))
    parser.add_argument("--out", metavar="DIR", help="output folder (default: reproduce/TABLE)")
    parser.add_argument(
        "--duration",
        type=seconds(allow_zero=False),
        metavar="S",
        help="seconds of each sequence (default: the paper's, table1 the first 25 s, table2 the whole "
        "sequences: §4.3 names no window and Fig. 4 shows the whole trajectories; rotation the protocol's 30 s)",
    )
    parser.add_argument(
        "--config",
        metavar="FILE",
        help="table1 and table2: configuration (default paper, the paper's); rotation's methods carry their own",
    )
    parser.add_argument(
        "--protocol",
        choices=("cmax-slam",),
        help="rotation: how its trajectories are scored (default cmax-slam, the only one: docs/rotation_benchmark.md)",
    )
    parser.add_argument(
        "--backends",
        metavar="A,B",
        help="table1's backends (default chain,gtsam): chain on klt's consecutive edges (the paper), "
        "any other fed also its keyframe edges (tracker.klt.keyframe_interval=3, as configs/best.toml)",
    )
    parser.add_argument(
        "--estimate",
        dest="estimates",
        action="append",
        default=[],
        metavar="SEQUENCE:SOURCE=FILE",
        help="table2: an ORB-SLAM2 KeyFrameTrajectory.txt, e.g. hdr_boxes:eas=KeyFrameTrajectory.txt (repeatable)",
    )
    parser.add_argument(
        "--frontends",
        metavar="A,B",
        help="table2's sources (default original,eas, the paper's); any frontend, e.g. original,histeq,eas,sits",
    )
    parser.add_argument(
        "--runs",
        type=positive_int,
        help="table2 with the slam extra: ORB-SLAM3 runs per cell (default 5; the median is reported)",
    )
    parser.add_argument(
        "--vocabulary",
        metavar="FILE",
        help="table2 with the slam extra: ORB vocabulary (default: $PYORBSLAM3_VOCAB, else ORBvoc.txt, fetched if missing)",
    )
    add_jobs(parser)
    add_quiet(parser, help="no progress bars")
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo reproduce` on the parsed `args`; returns the exit status."""
    from eas_vo.datasets.ecd_catalogue import data_dir
    from eas_vo.evaluation.rotation_protocol import ALIGN_AT_S
    from eas_vo.experiments import paper, rotation
    from eas_vo.io.outputs import check_grid_folder, check_writable_folder, removed_if_failed

    estimates = {}
    for text in args.estimates:
        key, sep, path = text.partition("=")
        seq, colon, source = key.partition(":")
        if not (sep and colon and path):
            raise UsageError(
                f"--estimate {text!r}: expected SEQUENCE:SOURCE=FILE, e.g. hdr_boxes:eas=KeyFrameTrajectory.txt"
            )
        key = (seq.strip(), source.strip())
        if key in estimates:
            raise UsageError(f"--estimate {key[0]}:{key[1]} given twice ({estimates[key]} and {path}): give one")
        estimates[key] = path
    if estimates and args.table != "table2":
        raise UsageError("--estimate belongs to table2 (ORB-SLAM2 trajectories)")
    if args.vocabulary and args.table != "table2":
        raise UsageError("--vocabulary belongs to table2 (ORB-SLAM3 runs)")
    if args.config and args.table == "rotation":
        raise UsageError(
            "--config belongs to table1 and table2: rotation's methods carry their own (paper.toml, best.toml)"
        )
    owners = {"backends": "table1", "frontends": "table2", "runs": "table2", "protocol": "rotation"}
    for key, table in owners.items():
        if getattr(args, key) is not None and args.table != table:
            raise UsageError(f"--{key} belongs to {table}")
    if args.table == "rotation" and args.duration is not None and args.duration <= ALIGN_AT_S:
        raise UsageError(f"--duration {args.duration:g}: the protocol aligns at {ALIGN_AT_S:g} s; give more than that")
    config = args.config or "paper"
    specs = rotation.SPECS if args.table == "rotation" else paper.SPECS
    out = check_writable_folder(args.out or f"reproduce/{args.table}")
    refuse_inputs_inside(
        out,
        [i for spec in specs.values() for i in dataset_inputs(spec)],
        ("the --config", config),
        ("the --vocabulary", args.vocabulary),
        ("the data folder", str(data_dir())),
        *(("the --estimate", path) for path in estimates.values()),
    )
    check_grid_folder(out)  # before any download
    with removed_if_failed(out):
        rows, n_run, markdown = _reproduce(args, out, config, estimates)
    return report_cells(rows, n_run, out / f"{args.table}.md", markdown)


def _reproduce(args, out, config: str, estimates: dict) -> tuple[list[dict], int, str]:
    """The table `args.table` written into `out`: (rows, cells run, its markdown)."""
    from eas_vo.evaluation.rotation_protocol import DURATION_S
    from eas_vo.experiments import paper, rotation, table1, table2

    progress = shows_progress(args)
    if args.table == "table1":
        return table1.table1(
            out,
            args.duration or paper.PAPER_DURATION_S,
            name_list("--backends", args.backends or "chain,gtsam"),
            config,
            args.jobs,
            progress,
        )
    if args.table == "rotation":
        return rotation.rotation_benchmark(out, args.duration or DURATION_S, args.jobs, progress)
    return table2.table2(
        out,
        estimates,
        args.duration,
        config,
        args.jobs,
        progress,
        name_list("--frontends", args.frontends or "original,eas"),
        args.runs or 5,
        args.vocabulary,
    )
