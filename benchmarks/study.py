"""What the research benchmarks share: the real recording they read (a folder in the Event
Camera Dataset's layout, or an ECD name such as `ecd:shapes_rotation`, fetched like `eas-vo
fetch` and unpacked once beside its zip), and `--smoke`, which runs a study's protocol on the
first SMOKE_S seconds of each sequence and the first item of each list it loops over: a check
that the command runs (the documentation's commands are run so by the tests), its figures mean
nothing."""

from __future__ import annotations

import argparse
import shutil
import tempfile
import zipfile
from pathlib import Path

from eas_vo.datasets.ecd_catalogue import fetch
from eas_vo.errors import EasVoError

#: The benchmarks' real recording unless --real names another: the Event Camera Dataset's
#: shapes_rotation (fetched on first use; offline, EAS_VO_DATA_DIR names a folder holding its zip).
DEFAULT = "ecd:shapes_rotation"


#: Seconds of each sequence a study reads under --smoke.
SMOKE_S = 1.0


def add_real(parser: argparse.ArgumentParser, help: str = "the real recording") -> None:
    """--real SPEC: a folder in the ECD layout or an ECD name; '' leaves the real data out
    where the benchmark can do without it."""
    parser.add_argument(
        "--real", default=DEFAULT, help=f"{help}: an ECD folder or name (default {DEFAULT}, fetched when missing)"
    )


def add_smoke(parser: argparse.ArgumentParser) -> None:
    """--smoke (the module's docstring)."""
    parser.add_argument(
        "--smoke",
        action="store_true",
        help=f"check that the command runs: the protocol on {SMOKE_S:g} s of each sequence and the first item of "
        "each list (its figures mean nothing)",
    )


def simulated_for(smoke: bool) -> list[str]:
    """`--set` assignments for an embedded synthetic sequence: under --smoke simulated for
    SMOKE_S seconds only (not its whole length, then cut)."""
    return [f"dataset.duration_s={SMOKE_S:g}"] if smoke else []


def first(items, smoke: bool) -> list:
    """`items` as a list, only its first under --smoke."""
    items = list(items)
    return items[:1] if smoke else items


def window(start_s: float, duration_s: float, smoke: bool) -> tuple[float, float]:
    """(start, duration) [s] of a study's window: under --smoke the first SMOKE_S seconds."""
    return (0.0, SMOKE_S) if smoke else (start_s, duration_s)


def real_folder(spec: str) -> Path:
    """The folder of `spec`: as given when it is one, else the ECD sequence it names (`ecd:NAME`
    or NAME) fetched and unpacked into the data folder (once; a whole folder or none)."""
    if Path(spec).is_dir():
        return Path(spec)
    name = spec.removeprefix("ecd:")
    try:
        archive = fetch(name, progress=True)
    except EasVoError as exc:
        raise SystemExit(f"--real {spec}: {exc}") from None
    folder = archive.with_suffix("")
    if not (folder / "images.txt").is_file():
        with tempfile.TemporaryDirectory(dir=archive.parent) as tmp:
            unpacked = Path(tmp) / name
            with zipfile.ZipFile(archive) as z:
                z.extractall(unpacked)
            inner = [p.parent for p in unpacked.rglob("images.txt")]
            if len(inner) != 1:
                raise SystemExit(f"{archive}: holds no single images.txt; not an ECD sequence")
            shutil.rmtree(folder, ignore_errors=True)
            inner[0].rename(folder)
    return folder
