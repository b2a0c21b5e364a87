"""The options several commands share, declared once, and the helpers that read them."""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from eas_vo.errors import EasVoError, UsageError


def installed_names(kind: str) -> str:
    """The installed plugins of `kind` (registry.KINDS), for a help text: from their entry
    points, so that a third party's are listed and `--help` imports none of them."""
    from eas_vo import registry

    return ", ".join(registry.names(kind))


def add_dataset(parser, help: str = "as for run (default: synthetic:default)", required: bool = False) -> None:
    """--dataset SPEC: the recording a command reads."""
    parser.add_argument("--dataset", required=required, metavar="SPEC", help=help)


def add_config(
    parser,
    config_help: str = "TOML config file, or the name of a bundled one (e.g. paper)",
    set_help: str = "override one config value, e.g. frontend.n=8000 (repeatable)",
) -> None:
    """--config FILE and --set SECTION.KEY=VALUE (repeatable, into args.assignments)."""
    parser.add_argument("--config", metavar="FILE", help=config_help)
    parser.add_argument(
        "--set", dest="assignments", action="append", default=[], metavar="SECTION.KEY=VALUE", help=set_help
    )


def add_window(parser) -> None:
    """--start and --duration [s]: the part of the sequence a command reads."""
    parser.add_argument(
        "--start", type=seconds(allow_zero=True), metavar="S", help="skip the first S seconds of the sequence"
    )
    parser.add_argument(
        "--duration", type=seconds(allow_zero=False), metavar="S", help="process S seconds (default: all)"
    )


def add_time_offset(parser) -> None:
    """--time-offset S|auto, for the commands that evaluate against ground truth."""
    parser.add_argument(
        "--time-offset",
        metavar="S|auto",
        help="ground truth is sampled at frame time + S seconds (default 0); 'auto' estimates S from the data",
    )


def add_quiet(parser, help: str = "no progress bar") -> None:
    """--quiet: no progress bar."""
    parser.add_argument("--quiet", action="store_true", help=help)


def add_lenient(parser) -> None:
    """--lenient: the dataset's reader tolerates (and counts) what it would refuse."""
    parser.add_argument(
        "--lenient",
        action="store_true",
        help="drop malformed lines, out-of-order or out-of-sensor events and missing frames, with counted warnings",
    )


def add_output_options(parser, required: bool, default: str | None = None) -> None:
    """--out and --overwrite, as every command writing one output folder has them."""
    where = f"default: {default}" if default else "new, or replaced with --overwrite"
    parser.add_argument("--out", required=required, metavar="DIR", help=f"output folder ({where})")
    parser.add_argument(
        "--overwrite", action="store_true", help="replace a non-empty --out that holds only an earlier eas-vo output"
    )


def add_threads(parser) -> None:
    """--threads N: the threads of eas-vo's own parallel work (concurrency.set_threads)."""
    parser.add_argument(
        "--threads",
        type=positive_int,
        metavar="N",
        help="threads for eas-vo's own parallel work (default: one per core; 1: the serial path, "
        "which gives the same results)",
    )


def apply_threads(args) -> None:
    """Use the --threads given (if any) for the rest of the process."""
    if getattr(args, "threads", None):
        from eas_vo import concurrency

        concurrency.set_threads(args.threads)


def add_jobs(parser) -> None:
    """--jobs N: the parallel processes of a grid (default: one per core)."""
    parser.add_argument(
        "--jobs", type=positive_int, default=os.cpu_count() or 1, help="parallel processes (default: all cores)"
    )


def positive_int(text: str) -> int:
    """argparse type: an integer of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def seconds(allow_zero: bool):
    """argparse type: a finite number of seconds, positive (or, with `allow_zero`, not negative)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
        if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(
                f"must be {'at least 0' if allow_zero else 'more than 0'} seconds, got {text}"
            )
        return value

    return parse


def set_assignments(args) -> list[str]:
    """The --set assignments after --lenient's (an option: --set overrides it)."""
    return (["dataset.lenient=true"] if args.lenient else []) + args.assignments


def window_overrides(args) -> dict:
    """The [run] values given by --start and --duration."""
    return {"start_s": args.start, "duration_s": args.duration}


def shared_overrides(args) -> dict:
    """The [run] values given by the window and --time-offset."""
    offset, auto = parse_time_offset(args.time_offset)
    return {**window_overrides(args), "time_offset_s": offset, "time_offset_auto": auto}


def parse_time_offset(text: str | None) -> tuple[float | None, bool | None]:
    """--time-offset value -> (offset_s, auto)."""
    if text is None:
        return None, None
    if text.strip().lower() == "auto":
        return None, True
    try:
        return float(text), False
    except ValueError:
        raise UsageError(f"--time-offset takes seconds or 'auto', got {text!r}") from None


def shows_progress(args) -> bool:
    """Whether to draw progress bars: not --quiet, and stderr is a terminal."""
    return not args.quiet and sys.stderr.isatty()


def name_list(option: str, text: str) -> list[str]:
    """A comma-separated list of names; one naming nothing is an error."""
    listed = [v.strip() for v in text.split(",") if v.strip()]
    if not listed:
        raise UsageError(f"{option} {text!r} names nothing; give comma-separated names")
    return listed


def dataset_inputs(spec: str, settings=None) -> list[tuple[str, str | None]]:
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
    return [
        ("the dataset", location),
        *(
            (what, value)
            for what, value in named
            if isinstance(value, str) and value and Path(value).expanduser().exists()
        ),
    ]


def dataset_settings(args, spec: str):
    """The [dataset] section `spec` resolves to under the command's --config and --set, or None
    when they do not resolve (the run that reads them says why)."""
    from eas_vo import config as config_mod

    try:
        return config_mod.resolve(args.config, {"dataset": spec}, args.assignments).dataset
    except EasVoError:
        return None


def refuse_inputs_inside(
    out: Path, datasets: list[tuple[str, str | None]], *others: tuple[str, str | None], out_is_file: bool = False
) -> None:
    """io.refuse_inputs for a command's output: its datasets' inputs (dataset_inputs) and the
    `others` it reads ((what, path or None): a --config, an --estimate, ...)."""
    from eas_vo.io.outputs import refuse_inputs

    refuse_inputs(out, [*datasets, *others], out_is_file=out_is_file)


def report_cells(rows: list[dict], n_run: int, table: Path, markdown: str) -> int:
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
