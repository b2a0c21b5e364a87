"""Command-line interface: `eas-vo run | compare | list | info | render | export | slam | vocabulary |
convert | evaluate | reproduce | fetch | cache | simulate`.

Each command is a pair here: `_parse_NAME` declares its arguments and help (the options several
commands share are declared once, in `_add_*`), and `cmd_NAME` turns the parsed arguments into a
call of the library function that does the work (eas_vo.pipeline, compare, sequence, ...) and
prints its result. User errors (bad data, bad config) end in one line on stderr and exit code 2.
Ctrl-C and SIGTERM end in one line saying what was kept, and exit code 130 / 143.
Heavy modules are imported inside the commands, so `--help` is instant.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from eas_vo.errors import EasVoError, Interrupted, sigterm_as_interrupt


def main(argv: list[str] | None = None) -> int:
    from eas_vo.logs import to_stderr; to_stderr()  # noqa: E702  (the library's log records on stderr)
    args = build_parser().parse_args(argv)
    try:
        with sigterm_as_interrupt():
            return args.func(args)
    except EasVoError as exc:
        print(f"eas-vo: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `eas-vo list | head`: the reader left; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # the machine's answer to a user's request (a full disk, a path in the way)
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"eas-vo: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # the one place: a command says what it kept in Interrupted
        kept = exc.kept if isinstance(exc, Interrupted) and exc.kept else "nothing was written"
        print(f"eas-vo {args.command}: interrupted; {kept}", file=sys.stderr)
        return 143 if isinstance(exc, Interrupted) and exc.sigterm else 130


class _OneLineParser(argparse.ArgumentParser):
    """A usage error is one line on stderr (with where to read more) and exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(
        prog="eas-vo",
        description="3-DoF rotation estimation from event cameras fused with frames (EAS and peers).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_OneLineParser)
    for add in (_parse_run, _parse_compare, _parse_list, _parse_info, _parse_render, _parse_export, _parse_slam,
                _parse_vocabulary, _parse_convert, _parse_evaluate, _parse_reproduce, _parse_fetch, _parse_cache, _parse_simulate):
        add(sub)
    return parser


# ----------------------------------------------------------------------------- shared options

def _installed(kind: str) -> str:
    """The installed plugins of `kind` (registry.KINDS), for a help text: from their entry
    points, so that a third party's are listed and `--help` imports none of them."""
    from eas_vo import registry

    return ", ".join(registry.names(kind))


def _add_dataset(parser, help: str = "as for run (default: synthetic:default)", required: bool = False) -> None:
    """--dataset SPEC: the recording a command reads."""
    parser.add_argument("--dataset", required=required, metavar="SPEC", help=help)


def _add_config(parser, config_help: str = "TOML config file, or the name of a bundled one (e.g. paper)",
                set_help: str = "override one config value, e.g. frontend.n=8000 (repeatable)") -> None:
    """--config FILE and --set SECTION.KEY=VALUE (repeatable, into args.assignments)."""
    parser.add_argument("--config", metavar="FILE", help=config_help)
    parser.add_argument("--set", dest="assignments", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help=set_help)


def _add_window(parser) -> None:
    """--start and --duration [s]: the part of the sequence a command reads."""
    parser.add_argument("--start", type=_seconds(allow_zero=True), metavar="S", help="skip the first S seconds of the sequence")
    parser.add_argument("--duration", type=_seconds(allow_zero=False), metavar="S", help="process S seconds (default: all)")


def _add_time_offset(parser) -> None:
    """--time-offset S|auto, for the commands that evaluate against ground truth."""
    parser.add_argument("--time-offset", metavar="S|auto",
                        help="ground truth is sampled at frame time + S seconds (default 0); 'auto' estimates S from the data")


def _add_quiet(parser, help: str = "no progress bar") -> None:
    parser.add_argument("--quiet", action="store_true", help=help)


def _add_lenient(parser) -> None:
    """--lenient: the dataset's reader tolerates (and counts) what it would refuse."""
    parser.add_argument(
        "--lenient",
        action="store_true",
        help="drop malformed lines, out-of-order or out-of-sensor events and missing frames, with counted warnings",
    )


def _add_output_options(parser, required: bool, default: str | None = None) -> None:
    """--out and --overwrite, as every command writing one output folder has them."""
    where = f"default: {default}" if default else "new, or replaced with --overwrite"
    parser.add_argument("--out", required=required, metavar="DIR", help=f"output folder ({where})")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace a non-empty --out that holds only an earlier eas-vo output")


def _add_threads(parser) -> None:
    parser.add_argument("--threads", type=_positive_int, metavar="N",
                        help="threads for eas-vo's own parallel work (default: one per core; 1: the serial path, "
                             "which gives the same results)")


def _apply_threads(args) -> None:
    if getattr(args, "threads", None):
        from eas_vo import concurrency

        concurrency.set_threads(args.threads)


def _add_jobs(parser) -> None:
    parser.add_argument("--jobs", type=_positive_int, default=os.cpu_count() or 1, help="parallel processes (default: all cores)")


def _positive_int(text: str) -> int:
    """argparse type: an integer of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _seconds(allow_zero: bool):
    """argparse type: a finite number of seconds, positive (or, with `allow_zero`, not negative)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
        if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(f"must be {'at least 0' if allow_zero else 'more than 0'} seconds, got {text}")
        return value
    return parse


def _assignments(args) -> list[str]:
    """The --set assignments after --lenient's (an option: --set overrides it)."""
    return (["dataset.lenient=true"] if args.lenient else []) + args.assignments


def _window_overrides(args) -> dict:
    """The [run] values given by --start and --duration."""
    return {"start_s": args.start, "duration_s": args.duration}


def _shared_overrides(args) -> dict:
    """The [run] values given by the window and --time-offset."""
    offset, auto = _time_offset(args.time_offset)
    return {**_window_overrides(args), "time_offset_s": offset, "time_offset_auto": auto}


def _time_offset(text: str | None) -> tuple[float | None, bool | None]:
    """--time-offset value -> (offset_s, auto)."""
    if text is None:
        return None, None
    if text.strip().lower() == "auto":
        return None, True
    try:
        return float(text), False
    except ValueError:
        raise EasVoError(f"--time-offset takes seconds or 'auto', got {text!r}") from None


def _progress(args) -> bool:
    """Whether to draw progress bars: not --quiet, and stderr is a terminal."""
    return not args.quiet and sys.stderr.isatty()


def _names(option: str, text: str) -> list[str]:
    """A comma-separated list of names; one naming nothing is an error."""
    listed = [v.strip() for v in text.split(",") if v.strip()]
    if not listed:
        raise EasVoError(f"{option} {text!r} names nothing; give comma-separated names")
    return listed


def _dataset_inputs(spec: str, settings=None) -> list[tuple[str, str | None]]:
    """The inputs (what, path) a dataset brings to a command: the recording `spec` names (None
    when it names none: whoever opens it says so) and each file or folder one of its [dataset]
    `settings` (the resolved section) names, such as a calibration or a ground-truth file."""
    from dataclasses import fields

    from eas_vo.registry import resolve_dataset

    try:
        location = resolve_dataset(spec)[1]
    except EasVoError:
        location = None
    named = [(f"dataset.{f.name}", getattr(settings, f.name)) for f in fields(settings)] if settings is not None else []
    return [("the dataset", location),
            *((what, value) for what, value in named if isinstance(value, str) and value and Path(value).expanduser().exists())]


def _dataset_settings(args, spec: str):
    """The [dataset] section `spec` resolves to under the command's --config and --set, or None
    when they do not resolve (the run that reads them says why)."""
    from eas_vo import config as config_mod

    try:
        return config_mod.resolve(args.config, {"dataset": spec}, args.assignments).dataset
    except EasVoError:
        return None


def _refuse_inputs_inside(out: Path, datasets: list[tuple[str, str | None]], *others: tuple[str, str | None],
                          out_is_file: bool = False) -> None:
    """io.refuse_inputs for a command's output: its datasets' inputs (_dataset_inputs) and the
    `others` it reads ((what, path or None): a --config, an --estimate, ...)."""
    from eas_vo.io import refuse_inputs

    refuse_inputs(out, [*datasets, *others], out_is_file=out_is_file)


# ----------------------------------------------------------------------------- run

EPILOG_RUN = """\
outputs (in --out):
  trajectory.tum   estimated camera-to-world rotation per frame (TUM: t tx ty tz qx qy qz qw)
  groundtruth.tum  ground truth at the same timestamps (when the dataset has it)
  metrics.json     average APE (Eq. 3, rad), RMSE, max, average NC, frames, timing
  frames.csv       per frame: index, t, NC, inliers, status (first, ok, weak, lost, same_time), redetected,
                   inlier ratio, residual [px], why the frame is weak or lost
  config.toml      the resolved configuration (re-run with --config config.toml)
  rotation.png     estimated and true roll/pitch/yaw over time

examples:
  eas-vo run --frontend eas --backend chain
  eas-vo run --dataset path/to/hdr_boxes --frontend original --start 0 --duration 25
  eas-vo run --frontend eas --set frontend.n=8000 --set tracker.threshold1=15
  eas-vo run --dataset ecd:path/to/folder --tracker klt --config best
"""


def _parse_run(sub) -> None:
    run = sub.add_parser(
        "run",
        help="estimate rotation on a sequence and evaluate it",
        description="Run one frontend + tracker + backend on a dataset and write the trajectory, metrics and plots.",
        epilog=EPILOG_RUN,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from eas_vo.config import RunConfig

    _add_dataset(run, help=f"a recording (a folder or file) one of the installed dataset plugins opens, or "
                 f"PLUGIN:LOCATION, PLUGIN one of {_installed('datasets')}; synthetic:NAME is simulated once "
                 f"(default {RunConfig.dataset}; eas-vo list says what each plugin reads)")
    run.add_argument("--frontend", metavar="NAME",
                     help=f"image source, one of {_installed('frontends')} (default {RunConfig.frontend})")
    run.add_argument("--tracker", metavar="NAME",
                     help=f"relative rotations between frames, one of {_installed('trackers')} "
                     f"(default {RunConfig.tracker}, the paper's)")
    run.add_argument("--backend", metavar="NAME",
                     help=f"relative -> absolute rotations, one of {_installed('backends')} (default {RunConfig.backend})")
    _add_config(run)
    _add_window(run)
    _add_time_offset(run)
    _add_quiet(run)
    _add_lenient(run)
    _add_threads(run)
    _add_output_options(run, required=False, default="runs/DATASET_FRONTEND_TRACKER_BACKEND_TIME")
    run.set_defaults(func=cmd_run)


def cmd_run(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo import pipeline
    from eas_vo.io import check_output_folder, slug

    _apply_threads(args)
    config = config_mod.resolve(
        args.config,
        {"dataset": args.dataset, "frontend": args.frontend, "tracker": args.tracker, "backend": args.backend,
         **_shared_overrides(args)},
        _assignments(args),
    )
    rc = config.run
    if args.out:
        out = check_output_folder(args.out, replace=args.overwrite)
        _refuse_inputs_inside(out, _dataset_inputs(rc.dataset, config.dataset), ("the --config", args.config))
    else:
        import time

        out = Path(f"runs/{slug(rc.dataset)}_{rc.frontend}_{rc.tracker}_{rc.backend}_{time.strftime('%Y%m%d-%H%M%S')}")
    result = pipeline.run(config, out, progress=_progress(args), replace=args.overwrite)
    m = result.metrics
    for line in m["data_warnings"]:
        print(f"eas-vo: warning: {line}", file=sys.stderr)
    ape = m.get("ape_mean_rad")
    ape_text = "no ground truth"
    if "frames_scored_fraction" in m:  # scored: over how many frames and what span of the run
        start, end = m["ground_truth_span_s"]
        scored = f"{m['frames_evaluated']} of {m['frames']} frames scored, ground truth from {start:.3f} to {end:.3f} s of the run's 0 to {m['sequence_s']:.3f} s"
        ape_text = f"average APE {ape:.4f} rad ({ape * 57.29577951:.2f} deg; {scored})" if m["frames_evaluated"] else f"no frame scored ({scored})"
    if m["time_offset_estimated"]:
        ape_text += f" (time offset {m['time_offset_s'] * 1e3:+.1f} ms, estimated on the ground truth it scores against)"
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
WEAK_MEANS = "weak: less reliable than usual, not necessarily wrong; 2-42 % of frames with the paper's settings"


def _status_text(counts: dict, reasons: dict) -> str:
    """'1 first, 54 ok, 172 weak: 160 low inlier ratio, 12 few inliers' (most frequent reason first)."""
    parts = []
    for status in ("first", "ok", "weak", "lost", "same_time"):
        if counts.get(status):
            why = sorted(reasons.get(status, {}).items(), key=lambda kv: (-kv[1], kv[0]))
            parts.append(f"{counts[status]} {status}" + (": " + ", ".join(f"{n} {r}" for r, n in why) if why else ""))
    return "; ".join(parts) if any(": " in p for p in parts) else ", ".join(parts)


# ----------------------------------------------------------------------------- compare

def _parse_compare(sub) -> None:
    compare = sub.add_parser(
        "compare",
        help="run a grid of datasets x frontends x trackers x backends (x sweeps); write the paper's Table 1",
        description="Run every cell (dataset x frontend x tracker x backend x sweep point) as `eas-vo run` would, "
        "in parallel processes; cells already complete are not run again. Writes table.md, table.csv, "
        "table.json (Table 1 of the paper: average NC and APE per source type), ape_bars.png, "
        "ape_time.png and each cell's own folder.",
    )
    compare.add_argument("--dataset", dest="datasets", action="append", metavar="SPEC",
                         help="a dataset (repeatable; default synthetic:default)")
    compare.add_argument("--frontends", metavar="A,B,...", help="default: the paper's six sources, original,histeq,slice,ts,sits,eas")
    compare.add_argument("--trackers", metavar="A,B,...", help="default: the config's [run] tracker (klt without --config)")
    compare.add_argument("--backends", metavar="A,B,...",
                         help="default: the config's [run] backend; where that is the paper's klt+chain (as without "
                         "--config), also klt+gtsam with keyframe edges (tracker.klt.keyframe_interval=3)")
    _add_config(compare)
    _add_window(compare)
    _add_time_offset(compare)
    _add_quiet(compare)
    compare.add_argument("--sweep", dest="sweeps", action="append", default=[], metavar="SECTION.KEY=V1,V2",
                         help="values to try (repeatable: the cartesian product is run)")
    compare.add_argument("--orb", action="store_true", help="also ORB keypoints and matches per source (Table 2)")
    _add_jobs(compare)
    compare.add_argument("--executor", choices=("local", "dask"), default="local",
                         help="local process pool (default), or an existing Dask distributed cluster")
    compare.add_argument("--scheduler", metavar="ADDRESS", help="the Dask scheduler, e.g. tcp://10.0.0.5:8786")
    compare.add_argument("--out", required=True, metavar="DIR",
                         help="the grid's folder: new, empty, or an earlier compare's, which is resumed")
    compare.set_defaults(func=cmd_compare)


def cmd_compare(args) -> int:
    from eas_vo import compare
    from eas_vo import config as config_mod
    from eas_vo.gallery import PAPER_ORDER
    from eas_vo.io import check_grid_folder, check_writable_folder
    from eas_vo.reproduce import default_methods

    out = check_writable_folder(args.out)
    run_defaults = config_mod.run_section(args.config, args.assignments)  # e.g. best.toml's tracker and backend
    datasets = args.datasets or [run_defaults.dataset]
    _refuse_inputs_inside(out, [i for spec in datasets for i in _dataset_inputs(spec, _dataset_settings(args, spec))],
                          ("the --config", args.config))
    check_grid_folder(out)
    if args.trackers or args.backends:
        methods = compare.grid_methods(_names("--trackers", args.trackers or run_defaults.tracker),
                                       _names("--backends", args.backends or run_defaults.backend))
    else:
        methods = default_methods(run_defaults.tracker, run_defaults.backend)
    cells = compare.plan(datasets, _names("--frontends", args.frontends or ",".join(PAPER_ORDER)), methods, args.sweeps)
    if args.executor == "dask" and not args.scheduler:
        raise EasVoError("--executor dask needs --scheduler ADDRESS")
    overrides = {**_shared_overrides(args), "orb_stats": True if args.orb else None}
    rows, n_run = compare.run_experiment(cells, out, args.config, args.assignments, overrides, args.jobs,
                                         progress=_progress(args),
                                         scheduler=args.scheduler if args.executor == "dask" else None)
    return _report_cells(rows, n_run, out / "table.md", compare.table_markdown(rows))


def _report_cells(rows: list[dict], n_run: int, table: Path, markdown: str) -> int:
    """Each failed cell in one line on stderr, then each data warning once with the cells it
    came from; the count and the table on stdout; exit 1 if a cell failed."""
    failed = [r for r in rows if r["status"] != "ok"]
    for r in failed:
        print(f"eas-vo: cell {r['folder']} failed: {r['error']}", file=sys.stderr)
    warned: dict[str, list[str]] = {}
    for r in rows:
        for line in r["data_warnings"]:
            warned.setdefault(line, []).append(r["folder"])
    for line, folders in warned.items():
        cells = ", ".join(folders[:3]) + (f" and {len(folders) - 3} more" if len(folders) > 3 else "")
        print(f"eas-vo: warning: {line} (cell{'s' if len(folders) > 1 else ''} {cells})", file=sys.stderr)
    print(f"{len(rows)} cells ({n_run} run, {len(rows) - n_run} already complete, {len(failed)} failed) -> {table}")
    print(markdown, end="")
    return 1 if failed else 0


# ----------------------------------------------------------------------------- list

def _parse_list(sub) -> None:
    lister = sub.add_parser(
        "list",
        help="list the installed datasets, frontends, trackers and backends with their config keys",
        description="Every plugin found through the entry-point groups eas_vo.datasets, eas_vo.frontends, "
        "eas_vo.trackers and eas_vo.backends: name, description, config keys with defaults.",
    )
    lister.set_defaults(func=cmd_list)


def cmd_list(args) -> int:
    from dataclasses import MISSING, fields

    from eas_vo import registry
    from eas_vo.config import RunConfig

    def config_keys(cls) -> str:
        keys = [f"{f.name}={f.default!r}" if f.default is not MISSING else f.name
                for f in fields(cls) if f.default is not MISSING or f.default_factory is MISSING]
        return " ".join(keys) if keys else "(none)"

    print(f"run (every run, [run] or --set run.KEY=VALUE):\n  {'':10s} config: {config_keys(RunConfig)}")
    for kind in registry.KINDS:
        for name, why in registry.broken_builtins(kind).items():
            print(f"eas-vo: warning: built-in {kind[:-1]} {name!r} failed to import: {why}", file=sys.stderr)
        print(f"{kind} (entry-point group eas_vo.{kind}):")
        for name, cls in registry.available(kind).items():
            print(f"  {name:10s} {cls.description}")
            print(f"  {'':10s} config: {config_keys(cls.Config)}")
            if kind == "datasets" and cls.catalogue():
                print(f"  {'':10s} fetch: {' '.join(sorted(cls.catalogue()))}")
    return 0


# ----------------------------------------------------------------------------- info

def _parse_info(sub) -> None:
    info = sub.add_parser(
        "info",
        help="say what a recording holds (streams, sensor, camera, spans, rates) before any long work",
        description="Open a dataset through its plugin and print the streams it holds (frames, events, IMU, ground "
        "truth), the sensor size, the camera model and intrinsics, and each stream's span, count and rate. "
        "Reads the frame list and at most one frame, and the event stream once (a text reader caches it for later runs).",
    )
    _add_dataset(info)
    _add_config(info, config_help="config file for the dataset's settings (its [dataset] table)",
                set_help="override one dataset setting, e.g. dataset.sample_rate_hz=100 (repeatable)")
    _add_lenient(info)
    info.set_defaults(func=cmd_info)


def cmd_info(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo.sequence import describe

    config = config_mod.resolve(args.config, {"dataset": args.dataset}, _assignments(args))
    print("\n".join(describe(config).lines()))
    return 0


# ----------------------------------------------------------------------------- render

def _parse_render(sub) -> None:
    render = sub.add_parser(
        "render",
        help="draw every frontend's image of chosen frames side by side (like the paper's Fig. 1)",
        description="Run every frontend (or --frontends) over a dataset up to the chosen frames and "
        "draw their images in a grid: one row per frame, one column per frontend.",
    )
    _add_dataset(render)
    render.add_argument("--frames", required=True, metavar="I,J,...", help="frame indices, e.g. 20,120")
    render.add_argument("--frontends", metavar="A,B,...", help="frontends to show (default: every installed one that makes an image)")
    _add_config(render, config_help="config file for the frontends' settings",
                set_help="override one config value, e.g. frontend.n=8000 (repeatable)")
    render.add_argument("--out", required=True, metavar="PNG", help="output image, e.g. gallery.png")
    render.add_argument("--overwrite", action="store_true", help="replace an existing --out if it is a PNG image (never one of the inputs)")
    render.set_defaults(func=cmd_render)


def cmd_render(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo.gallery import frontend_images
    from eas_vo.io import atomic_path, check_output_file, refuse_foreign_file
    from eas_vo.plots import plot_gallery

    out = check_output_file(args.out, replace=args.overwrite)
    try:
        frames = [int(v) for v in args.frames.split(",") if v.strip()]
    except ValueError:
        raise EasVoError(f"--frames takes comma-separated frame indices, got {args.frames!r}") from None
    if not frames:
        raise EasVoError("--frames names no frame")
    config = config_mod.resolve(args.config, {"dataset": args.dataset}, args.assignments)
    dataset = config.run.dataset
    _refuse_inputs_inside(out, _dataset_inputs(dataset, config.dataset), ("the --config", args.config), out_is_file=True)
    refuse_foreign_file(out, "PNG image")
    frontends = [v.strip() for v in args.frontends.split(",")] if args.frontends else None
    names, images = frontend_images(args.dataset, frames, frontends, args.config, args.assignments)
    with atomic_path(out) as tmp:
        plot_gallery(tmp, names, images, frames, title=dataset)
    print(f"wrote {len(frames)} frame(s) x {len(names)} frontend(s) to {out}")
    return 0


# ----------------------------------------------------------------------------- export

def _parse_export(sub) -> None:
    export = sub.add_parser(
        "export",
        help="write a frontend's images as a sequence ORB-SLAM2 reads (TUM or EuRoC layout) with its settings.yaml",
        description="Run a frontend (e.g. original or eas) over a dataset window and write its images in the "
        "layout monocular ORB-SLAM2/ORB-SLAM3 examples read, plus settings.yaml (the dataset's calibration in "
        "ORB-SLAM2's format, its frame rate, ORB-SLAM2's ORB extractor defaults): the paper's §4.3.",
        epilog="then, e.g.: ./Examples/Monocular/mono_tum Vocabulary/ORBvoc.txt OUT/settings.yaml OUT  "
        "(writes KeyFrameTrajectory.txt; score it with eas-vo evaluate)",
    )
    _add_dataset(export)
    export.add_argument("--frontend", metavar="NAME", help="image source (default eas)")
    export.add_argument("--format", choices=("tum", "euroc"), default="tum",
                        help="tum: rgb.txt + rgb/T.png (mono_tum); euroc: mav0/cam0/data/T_NS.png + timestamps.txt (mono_euroc)")
    _add_config(export)
    _add_window(export)
    _add_quiet(export)
    _add_output_options(export, required=True)
    export.set_defaults(func=cmd_export)


def cmd_export(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo.io import check_output_folder
    from eas_vo.orbslam import export

    config = config_mod.resolve(
        args.config,
        {"dataset": args.dataset, "frontend": args.frontend, **_window_overrides(args)},
        args.assignments,
    )
    out = check_output_folder(args.out, replace=args.overwrite)
    _refuse_inputs_inside(out, _dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config))
    done = export(config, out, args.format, progress=_progress(args), replace=args.overwrite)
    print(f"wrote {done['frames']} {done['frontend']} images of {done['dataset']} ({done['format']} layout, "
          f"{done['fps']:.2f} frames/s) and settings.yaml to {out}")
    return 0


# ----------------------------------------------------------------------------- slam

EPILOG_SLAM = """\
outputs (in --out):
  run_R/frames.csv      per frame: index, t, state (not_initialised, ok, recently_lost, lost, relocalised),
                        tracked map points, the pose ORB-SLAM3 gave then (camera-to-world, its map's frame;
                        empty for a frame it did not track)
  run_R/keyframes.tum   the keyframe trajectory; run_R/trajectory.tum each tracked frame once (untracked ones
                        have no line), both after ORB-SLAM3's final optimisation
  run_R/metrics.json    status (ok: from the first initialisation on, >= 90 % of the frames tracked and the last;
                        never_initialised, lost, crashed), time to first initialisation, fractions tracked,
                        Sim(3) APE of both trajectories [m, rad]
  run_R/settings.yaml, run_R/slam.log   what ORB-SLAM3 read and printed
  summary.md, summary.json              median, min and max over the runs that tracked; ORB features and matches

examples:
  eas-vo vocabulary --dataset synthetic:walk --frontend original --out walk.voc.txt
  eas-vo slam --dataset synthetic:walk --frontend original --vocabulary walk.voc.txt --out slam_walk
  eas-vo fetch orb-vocabulary && eas-vo slam --dataset ecd:hdr_boxes --frontend eas --duration 25 --out slam_boxes
"""


def _parse_slam(sub) -> None:
    slam = sub.add_parser(
        "slam",
        help="run monocular ORB-SLAM3 on a frontend's images and score it (the paper's Table 2; extra: slam)",
        description="Feed a frontend's images of the window frame by frame to monocular ORB-SLAM3 (pyorbslam3, "
        "in a child process; settings from the dataset's calibration), --runs times (its threads make each run "
        "differ), and score each run's keyframe and all-frame trajectories against ground truth after Sim(3) "
        "alignment. Each frame is sent once ORB-SLAM3's mapping threads are idle, so a busy machine changes how long a run "
        "takes, not what it tracks. A run that never initialises, loses track or crashes is reported as such.",
        epilog=EPILOG_SLAM, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_dataset(slam)
    slam.add_argument("--frontend", metavar="NAME", help="image source (default eas)")
    slam.add_argument("--vocabulary", metavar="FILE",
                      help="DBoW2 text vocabulary (default: $PYORBSLAM3_VOCAB, else ORBvoc.txt from eas-vo fetch orb-vocabulary)")
    slam.add_argument("--runs", type=_positive_int, default=5, help="runs (default 5, as the ORB-SLAM papers report)")
    _add_config(slam)
    _add_window(slam)
    _add_quiet(slam)
    _add_output_options(slam, required=True)
    slam.set_defaults(func=cmd_slam)


def cmd_slam(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo.io import check_output_folder, figure_text
    from eas_vo.slam.run import SUMMARISED, find_vocabulary, require_extra, run_slam

    require_extra()
    vocabulary = find_vocabulary(args.vocabulary)
    config = config_mod.resolve(args.config, {"dataset": args.dataset, "frontend": args.frontend, **_window_overrides(args)},
                                args.assignments)
    out = check_output_folder(args.out, replace=args.overwrite)
    _refuse_inputs_inside(out, _dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config),
                          ("the --vocabulary", str(vocabulary)))
    done = run_slam(config, out, str(vocabulary), args.runs, progress=_progress(args), replace=args.overwrite)
    statuses = ", ".join(f"{n} {s}" for s, n in done["statuses"].items())
    print(f"ORB-SLAM3 on {done['frames']} {done['frontend']} images of {done['dataset']}: {done['runs']} run(s), {statuses} -> {out}")
    for key, text in SUMMARISED:
        s = done[key]
        if s:
            print(f"  {text}: median {figure_text(s['median'], 4)} (min {figure_text(s['min'], 4)}, "
                  f"max {figure_text(s['max'], 4)}, {s['n']} run(s))")
    if not done["statuses"].get("ok"):
        print("  no run tracked: " + "; ".join(f"run {m['run']} {m['status']}" for m in done["per_run"]))
    for line in done["crashed"]:
        print(f"eas-vo: error: {line}", file=sys.stderr)
    return 2 if done["crashed"] else 0


def _parse_vocabulary(sub) -> None:
    vocabulary = sub.add_parser(
        "vocabulary",
        help="train a DBoW2 ORB vocabulary (ORB-SLAM's text format) on a sequence's own images",
        description="Extract ORB descriptors (ORB-SLAM's extractor settings) from every image of a frontend over "
        "the window and cluster them by hierarchical k-majority on Hamming distance, as DBoW2 does; word weights "
        "are inverse document frequencies over the images. Small by default: k=10 branches, L=4 levels (up to "
        "10^4 words; ORB-SLAM's ORBvoc.txt has 10^6).",
    )
    _add_dataset(vocabulary)
    vocabulary.add_argument("--frontend", metavar="NAME", help="image source (default eas)")
    vocabulary.add_argument("--k", type=_positive_int, default=10, help="branches per node (default 10)")
    vocabulary.add_argument("--levels", type=_positive_int, default=4, help="levels L (default 4)")
    vocabulary.add_argument("--seed", type=int, default=0, help="random seed of the clustering (default 0)")
    _add_config(vocabulary)
    _add_window(vocabulary)
    _add_quiet(vocabulary)
    vocabulary.add_argument("--out", required=True, metavar="FILE", help="the vocabulary file to write")
    vocabulary.add_argument("--overwrite", action="store_true", help="replace an existing --out if it is a vocabulary (never one of the inputs)")
    vocabulary.set_defaults(func=cmd_vocabulary)


def cmd_vocabulary(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo.io import check_output_file, refuse_foreign_file
    from eas_vo.slam.train import train_vocabulary

    config = config_mod.resolve(args.config, {"dataset": args.dataset, "frontend": args.frontend, **_window_overrides(args)},
                                args.assignments)
    out = check_output_file(args.out, replace=args.overwrite)
    _refuse_inputs_inside(out, _dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config),
                          out_is_file=True)
    refuse_foreign_file(out, "DBoW2 vocabulary")
    done = train_vocabulary(config, out, args.k, args.levels, args.seed, progress=_progress(args))
    print(f"wrote a vocabulary of {done['nodes']} nodes ({done['words']} words, k={args.k}, L={args.levels}) from "
          f"{done['descriptors']} ORB descriptors of {done['images']} {done['frontend']} images of {done['dataset']} to {out}")
    return 0


# ----------------------------------------------------------------------------- convert

def _parse_convert(sub) -> None:
    convert = sub.add_parser(
        "convert",
        help="write any readable sequence (or a window of it) as an Event Camera Dataset folder",
        description="Read a dataset through its plugin and write it in the Event Camera Dataset text layout: "
        "images/ and images.txt (the APS frames, as PNG; none for an event-only stream), events.txt, imu.txt "
        "and groundtruth.txt (when it has them) and calib.txt. With --start/--duration, the frames of that "
        "window, the events from the frame before it to the frame after it, and the IMU readings and poses "
        "over that span and one more at each end. The folder is written whole, or not at all.",
        epilog="then, e.g.: eas-vo run --dataset OUT --config paper",
    )
    _add_dataset(convert)
    _add_config(convert, config_help="config file for the dataset's settings (its [dataset] table)",
                set_help="override one dataset setting, e.g. dataset.sample_rate_hz=100 (repeatable)")
    _add_window(convert)
    _add_quiet(convert)
    _add_lenient(convert)
    _add_output_options(convert, required=True)
    convert.set_defaults(func=cmd_convert)


def cmd_convert(args) -> int:
    from eas_vo import config as config_mod
    from eas_vo.io import check_output_folder
    from eas_vo.sequence import convert

    config = config_mod.resolve(args.config, {"dataset": args.dataset, **_window_overrides(args)}, _assignments(args))
    out = check_output_folder(args.out, replace=args.overwrite)
    _refuse_inputs_inside(out, _dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config))
    done = convert(config, out, progress=_progress(args), replace=args.overwrite)
    for line in done.warnings:
        print(f"eas-vo: warning: {line}", file=sys.stderr)
    print(f"wrote {done.frames} frames, {done.events} events, {done.imu} IMU readings and {done.poses} poses of "
          f"{done.label} ({done.span_s:.3f} s) as an Event Camera Dataset folder to {out}")
    if not done.frames:
        width, height = done.sensor
        print(f"  an event-only stream: open it with --set dataset.width={width} --set dataset.height={height} "
              "(without frames, its sensor size is not in the folder)")
    return 0


# ----------------------------------------------------------------------------- evaluate

def _parse_evaluate(sub) -> None:
    evaluate = sub.add_parser(
        "evaluate",
        help="score an external TUM trajectory (e.g. ORB-SLAM2's KeyFrameTrajectory.txt) against ground truth",
        description="Associate the estimate's poses with the dataset's ground truth (nearest time within "
        "--max-diff), align them (sim3: Umeyama with scale, for monocular SLAM; se3; origin) and report the "
        "translation APE [m] and rotation APE [rad], as evo_ape tum GT EST -as / -a / --align_origin does. "
        "With --out: metrics.json, table2_row.md, groundtruth.tum, estimate_aligned.tum.",
    )
    _add_dataset(evaluate, help="the dataset the estimate was made on", required=True)
    evaluate.add_argument("--estimate", required=True, metavar="FILE", help="TUM trajectory: t tx ty tz qx qy qz qw")
    evaluate.add_argument("--align", choices=("sim3", "se3", "origin"), default="sim3", help="default sim3 (evo_ape -as)")
    evaluate.add_argument("--max-diff", type=_seconds(allow_zero=True), default=0.01, metavar="S",
                          help="largest time difference of an associated pose pair (default 0.01 s, evo's)")
    evaluate.add_argument("--label", metavar="TEXT", help="the row's name in table2_row.md (default: the file's name)")
    _add_output_options(evaluate, required=False)
    evaluate.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args) -> int:
    from eas_vo.io import check_output_folder, figure_text
    from eas_vo.orbslam import evaluate_estimate

    if args.out:
        out = check_output_folder(args.out, replace=args.overwrite)
        _refuse_inputs_inside(out, _dataset_inputs(args.dataset), ("the --estimate", args.estimate))
    m = evaluate_estimate(args.dataset, args.estimate, args.align, args.max_diff, args.out, args.label,
                          replace=args.overwrite)
    for line in m["warnings"]:
        print(f"eas-vo: warning: {line}", file=sys.stderr)
    print(f"{args.estimate} vs {m['dataset']} ({m['align']}, {m['matched_poses']} of {m['estimate_poses']} poses matched, "
          f"scale {m['scale']:.4g}): translation APE mean {figure_text(m['ape_trans_mean_m'], 4)} m, "
          f"RMSE {figure_text(m['ape_trans_rmse_m'], 4)} m; rotation APE mean {m['ape_rot_mean_rad']:.4f} rad" + (f" -> {args.out}" if args.out else ""))
    return 0


# ----------------------------------------------------------------------------- reproduce

def _parse_reproduce(sub) -> None:
    reproduce = sub.add_parser(
        "reproduce",
        help="the paper's Table 1 or Table 2 on its own data (hdr_boxes, hdr_poster), beside its figures",
        description="table1: fetch hdr_boxes and hdr_poster, run the six sources with --config paper on the first "
        "25 s (time offset estimated) with both backends, and write table1.md (ours beside the paper's, ratios, "
        "orderings), compare's tables and figures, and Fig. 3-style Euler plots. table2: ORB features and matches "
        "of original and EAS images (or --frontends) and the keyframe APE after Sim(3) alignment of monocular SLAM "
        "on them: with the slam extra, --runs runs of ORB-SLAM3 per cell (eas-vo slam; ORBvoc.txt fetched unless "
        "--vocabulary), and for ORB-SLAM2 keyframe trajectories given with --estimate (run it on `eas-vo export` "
        "output), those; table2.md beside the paper's and Fig. 4-style keyframe plots. Resumable: the same command "
        "runs only what is missing.",
    )
    reproduce.add_argument("table", choices=("table1", "table2"))
    reproduce.add_argument("--out", metavar="DIR", help="output folder (default: reproduce/TABLE)")
    reproduce.add_argument("--duration", type=_seconds(allow_zero=False), metavar="S",
                           help="seconds of each sequence (default: the paper's, table1 the first 25 s, table2 the whole "
                           "sequences: §4.3 names no window and Fig. 4 shows the whole trajectories)")
    reproduce.add_argument("--config", default="paper", metavar="FILE", help="configuration (default paper, the paper's)")
    reproduce.add_argument("--backends", default="chain,gtsam", metavar="A,B",
                           help="table1's backends (default chain,gtsam): chain on klt's consecutive edges (the paper), "
                           "any other fed also its keyframe edges (tracker.klt.keyframe_interval=3, as configs/best.toml)")
    reproduce.add_argument("--estimate", dest="estimates", action="append", default=[], metavar="SEQUENCE:SOURCE=FILE",
                           help="table2: an ORB-SLAM2 KeyFrameTrajectory.txt, e.g. hdr_boxes:eas=KeyFrameTrajectory.txt (repeatable)")
    reproduce.add_argument("--frontends", default="original,eas", metavar="A,B",
                           help="table2's sources (default original,eas, the paper's); any frontend, e.g. original,histeq,eas,sits")
    reproduce.add_argument("--runs", type=_positive_int, default=5,
                           help="table2 with the slam extra: ORB-SLAM3 runs per cell (default 5; the median is reported)")
    reproduce.add_argument("--vocabulary", metavar="FILE",
                           help="table2 with the slam extra: ORB vocabulary (default: $PYORBSLAM3_VOCAB, else ORBvoc.txt, fetched if missing)")
    _add_jobs(reproduce)
    _add_quiet(reproduce, help="no progress bars")
    reproduce.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args) -> int:
    from eas_vo import reproduce
    from eas_vo.datasets.ecd_catalogue import data_dir
    from eas_vo.io import check_grid_folder, check_writable_folder

    estimates = {}
    for text in args.estimates:
        key, sep, path = text.partition("=")
        seq, colon, source = key.partition(":")
        if not (sep and colon and path):
            raise EasVoError(f"--estimate {text!r}: expected SEQUENCE:SOURCE=FILE, e.g. hdr_boxes:eas=KeyFrameTrajectory.txt")
        key = (seq.strip(), source.strip())
        if key in estimates:
            raise EasVoError(f"--estimate {key[0]}:{key[1]} given twice ({estimates[key]} and {path}): give one")
        estimates[key] = path
    if estimates and args.table != "table2":
        raise EasVoError("--estimate belongs to table2 (ORB-SLAM2 trajectories)")
    if args.vocabulary and args.table != "table2":
        raise EasVoError("--vocabulary belongs to table2 (ORB-SLAM3 runs)")
    out = check_writable_folder(args.out or f"reproduce/{args.table}")
    _refuse_inputs_inside(out, [i for spec in reproduce.SPECS.values() for i in _dataset_inputs(spec)],
                          ("the --config", args.config), ("the --vocabulary", args.vocabulary),
                          ("the data folder", str(data_dir())), *(("the --estimate", path) for path in estimates.values()))
    check_grid_folder(out)  # before any download
    progress = _progress(args)
    if args.table == "table1":
        rows, n_run, markdown = reproduce.table1(out, args.duration or reproduce.PAPER_DURATION_S,
                                                 _names("--backends", args.backends), args.config,
                                                 args.jobs, progress)
    else:
        rows, n_run, markdown = reproduce.table2(out, estimates, args.duration, args.config, args.jobs, progress,
                                                 _names("--frontends", args.frontends), args.runs, args.vocabulary)
    return _report_cells(rows, n_run, out / f"{args.table}.md", markdown)


# ----------------------------------------------------------------------------- fetch

#: The `eas-vo fetch` name of ORB-SLAM3's published vocabulary (ORBvoc.txt).
ORB_VOCABULARY = "orb-vocabulary"


def _parse_fetch(sub) -> None:
    fetch = sub.add_parser(
        "fetch",
        help="download Event Camera Dataset sequences (verified against their published MD5) or ORB-SLAM3's vocabulary",
        description="Download recordings by name (e.g. hdr_boxes hdr_poster; `eas-vo list` shows the catalogue) "
        "as the dataset publishes them, check each against its MD5, and skip those already there and whole. "
        "A download goes to a temporary file moved into place only once verified; an interrupted one is "
        "restarted by the same command. --dataset ecd:NAME then opens it (and fetches it if missing). "
        "`orb-vocabulary` downloads ORB-SLAM3's ORBvoc.txt (checked against the SHA-1 of its archive) for eas-vo slam.",
        epilog="environment: EAS_VO_DATA_DIR (default folder), EAS_VO_DATA_URL (a mirror), "
        "EAS_VO_DATA_REGISTRY (a file of 'name md5' lines replacing the built-in registry), "
        "EAS_VO_ORB_VOCABULARY_URL (a mirror of ORBvoc.txt.tar.gz)",
    )
    fetch.add_argument("names", nargs="+", metavar="NAME", help="a sequence name, PLUGIN:NAME, or orb-vocabulary")
    fetch.add_argument("--dir", metavar="DIR", help="where to keep them (default: $EAS_VO_DATA_DIR, else the cache's data/)")
    fetch.set_defaults(func=cmd_fetch)


def cmd_fetch(args) -> int:
    from eas_vo.registry import fetchable

    wanted = [fetchable(spec) for spec in args.names if spec != ORB_VOCABULARY]  # every name checked before any download
    if ORB_VOCABULARY in args.names:
        from eas_vo.slam.orbvoc import fetch_orb_vocabulary

        print(f"{ORB_VOCABULARY}: {fetch_orb_vocabulary(args.dir, progress=sys.stderr.isatty())} (verified)")
    for plugin, name in wanted:
        path = plugin.fetch(name, args.dir, progress=sys.stderr.isatty())
        print(f"{name}: {path} (verified)")
    return 0


# ----------------------------------------------------------------------------- cache

def _parse_cache(sub) -> None:
    cache = sub.add_parser(
        "cache",
        help="show, or clear, what eas-vo keeps in its cache folder",
        description="List each folder of the cache (event caches, simulated sequences, downloads, ...) with "
        "its entries and size; --clear NAME empties one (repeatable). Everything there is rebuilt, simulated "
        "or downloaded again when next needed; clear it while no eas-vo run is using it.",
        epilog="environment: EAS_VO_CACHE_DIR (the cache folder; default $XDG_CACHE_HOME/eas-vo or ~/.cache/eas-vo)",
    )
    cache.add_argument("--clear", action="append", default=[], metavar="NAME", help="empty this cache folder (e.g. events)")
    cache.set_defaults(func=cmd_cache)


def cmd_cache(args) -> int:
    from eas_vo.io import cache_dir, cache_usage, clear_cache

    if args.clear:
        for name, freed in clear_cache(args.clear).items():
            print(f"{name}: cleared, {_size(freed)} freed")
        return 0
    usage = cache_usage()
    print(f"{cache_dir()}:")
    for name, part in usage.items():
        where = f" (a link to {(cache_dir() / name).resolve()})" if part.link else ""
        print(f"  {name:10s} {part.entries:5d} entries {_size(part.size):>9s}  {part.about}{where}")
    total = sum(part.size for part in usage.values())
    print(f"  total {_size(total)}" + ("; eas-vo cache --clear NAME empties one" if usage else " (empty)"))
    return 0


def _size(n_bytes: int) -> str:
    """Bytes as text in B, kB, MB or GB."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.1f} {unit}"
    return f"{n_bytes} B"


# ----------------------------------------------------------------------------- simulate

def _parse_simulate(sub) -> None:
    sim = sub.add_parser(
        "simulate",
        help="write a synthetic dim-scene DAVIS sequence (ECD layout)",
        description="Simulate a textured HDR room seen by a hand-held DAVIS240 (or another camera: "
        "--set dataset.sensor=davis346, dataset.width=W dataset.height=H, dataset.lens=equidistant "
        "dataset.dist=[k1,k2,k3,k4]): APS frames, events, ground truth (200 Hz), IMU (200 Hz) and the "
        "calibration (calib.txt; camchain.yaml, kalibr's, for a fisheye) in the Event Camera Dataset text layout.",
    )
    _add_output_options(sim, required=True)
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--duration", type=float, default=10.0, metavar="S", help="length in seconds (default 10)")
    sim.add_argument("--illumination", type=float, metavar="X",
                     help="scale of the scene's light (default 1.0, the dim room; 0.1 is ten times darker)")
    sim.add_argument("--speed", type=float, metavar="X",
                     help="scale of the camera's speed (default 1.0, hand-held: 44 deg/s mean; 4 gives 177 deg/s, "
                     "more than the real shapes_rotation's 147): the same path, travelled X times as fast")
    sim.add_argument("--set", dest="assignments", action="append", default=[], metavar="dataset.KEY=VALUE",
                     help="a camera or DVS pixel value, as for run (see `eas-vo list`: the synthetic dataset's keys)")
    sim.add_argument("--stats", action="store_true",
                     help="print what the simulator knows of its events: rate, noise fraction, noise rate "
                     "per pixel and median latency in dark and bright regions")
    sim.set_defaults(func=cmd_simulate)


def cmd_simulate(args) -> int:
    from eas_vo.config import build, parse_set
    from eas_vo.datasets.simulator import SimConfig, simulate
    from eas_vo.datasets.synthetic import SyntheticConfig
    from eas_vo.io import check_output_folder, output_folder

    pixel = {}
    for assignment in args.assignments:
        keys, value = parse_set(assignment)
        if keys[0] != "dataset" or len(keys) != 2:
            raise EasVoError(f"--set {assignment!r}: simulate takes dataset.KEY=VALUE (the synthetic dataset's keys)")
        pixel[keys[1]] = value
    flags = {key: value for key, value in (("illumination", args.illumination), ("speed", args.speed)) if value is not None}
    for key in sorted(flags.keys() & pixel.keys()):
        raise EasVoError(f"--{key} and --set dataset.{key} both given: give one")
    sensor = build(SyntheticConfig, {**pixel, **flags}, "dataset")
    config = sensor.applied_to(build(SimConfig, {"seed": args.seed, "duration_s": args.duration}, "simulate"))
    check_output_folder(args.out, replace=args.overwrite)
    with output_folder(args.out, replace=args.overwrite, keep_partial=False) as staging:  # whole, or not at all
        stats = simulate(config, staging, progress=sys.stderr.isatty())
    cam = config.camera
    print(f"wrote a {config.duration_s:g} s synthetic sequence (seed {config.seed}, illumination {config.illumination:g}, "
          f"speed {config.speed:g}, {cam.width}x{cam.height} {cam.lens}) to {args.out}")
    if args.stats:
        print("\n".join("  " + line for line in stats.lines()))
    return 0
