"""`eas-vo compare`: a grid of runs and its tables."""

from __future__ import annotations

from eas_vo.cli.options import (
    add_config,
    add_jobs,
    add_quiet,
    add_time_offset,
    add_window,
    dataset_inputs,
    dataset_settings,
    name_list,
    refuse_inputs_inside,
    report_cells,
    shared_overrides,
    shows_progress,
)
from eas_vo.errors import UsageError


def add_parser(sub) -> None:
    """`eas-vo compare`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "compare",
        help="run a grid of datasets x frontends x trackers x backends (x sweeps); write the paper's Table 1",
        description="Run every cell (dataset x frontend x tracker x backend x sweep point) as `eas-vo run` would, "
        "in parallel processes; cells already complete are not run again. Writes table.md, table.csv, "
        "table.json (Table 1 of the paper: average NC and APE per source type), ape_bars.png, "
        "ape_time.png and each cell's own folder.",
    )
    parser.add_argument(
        "--dataset",
        dest="datasets",
        action="append",
        metavar="SPEC",
        help="a dataset (repeatable; default synthetic:default)",
    )
    parser.add_argument(
        "--frontends", metavar="A,B,...", help="default: the paper's six sources, original,histeq,slice,ts,sits,eas"
    )
    parser.add_argument(
        "--trackers", metavar="A,B,...", help="default: the config's [run] tracker (klt without --config)"
    )
    parser.add_argument(
        "--backends",
        metavar="A,B,...",
        help="default: the config's [run] backend; where that is the paper's klt+chain (as without "
        "--config), also klt+gtsam with keyframe edges (tracker.klt.keyframe_interval=3)",
    )
    add_config(parser)
    add_window(parser)
    add_time_offset(parser)
    add_quiet(parser)
    parser.add_argument(
        "--sweep",
        dest="sweeps",
        action="append",
        default=[],
        metavar="SECTION.KEY=V1,V2",
        help="values to try (repeatable: the cartesian product is run)",
    )
    parser.add_argument("--orb", action="store_true", help="also ORB keypoints and matches per source (Table 2)")
    add_jobs(parser)
    parser.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="local process pool (default), or an existing Dask distributed cluster",
    )
    parser.add_argument("--scheduler", metavar="ADDRESS", help="the Dask scheduler, e.g. tcp://10.0.0.5:8786")
    parser.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="the grid's folder: new, empty, or an earlier compare's, which is resumed",
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo compare` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.experiments import grid, results
    from eas_vo.experiments.cells import grid_methods, plan
    from eas_vo.experiments.gallery import PAPER_ORDER
    from eas_vo.experiments.paper import default_methods
    from eas_vo.io.outputs import check_grid_folder, check_writable_folder, removed_if_failed

    out = check_writable_folder(args.out)
    run_defaults = config_mod.run_section(args.config, args.assignments)  # e.g. best.toml's tracker and backend
    datasets = args.datasets or [run_defaults.dataset]
    refuse_inputs_inside(
        out,
        [i for spec in datasets for i in dataset_inputs(spec, dataset_settings(args, spec))],
        ("the --config", args.config),
    )
    check_grid_folder(out)
    if args.trackers or args.backends:
        methods = grid_methods(
            name_list("--trackers", args.trackers or run_defaults.tracker),
            name_list("--backends", args.backends or run_defaults.backend),
        )
    else:
        methods = default_methods(run_defaults.tracker, run_defaults.backend)
    cells = plan(datasets, name_list("--frontends", args.frontends or ",".join(PAPER_ORDER)), methods, args.sweeps)
    if args.executor == "dask" and not args.scheduler:
        raise UsageError("--executor dask needs --scheduler ADDRESS")
    overrides = {**shared_overrides(args), "orb_stats": True if args.orb else None}
    with removed_if_failed(out):
        rows, n_run = grid.run_experiment(
            cells,
            out,
            args.config,
            args.assignments,
            overrides,
            args.jobs,
            progress=shows_progress(args),
            scheduler=args.scheduler if args.executor == "dask" else None,
        )
    return report_cells(rows, n_run, out / "table.md", results.table_markdown(rows))
