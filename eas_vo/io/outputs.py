"""Output folders and files: what may be written or replaced (never an input, never a
foreign file), and the staging that gives a folder one whole run or one marked partial."""

from __future__ import annotations

import os
import re
import shutil
from contextlib import contextmanager
from pathlib import Path

from eas_vo.errors import EasVoError
from eas_vo.io.atomic import atomic_path, name_the_written, remove_stale_temporaries, write_text_atomic
from eas_vo.io.locks import acquire_lock

#: The file that marks a folder as an eas-vo output (a run, an export, an evaluation) and lists
#: the files eas-vo wrote there: only such a folder, holding nothing else, or an empty one, is
#: ever replaced.
OUTPUT_MARKER = ".eas-vo-output"


def resolved_out(out: str | Path) -> Path:
    """The absolute output path `out` (~ expanded, symlinks followed), or a one-line error naming
    it when its links loop or it cannot be resolved."""
    try:
        return Path(out).expanduser().resolve()
    except RuntimeError:  # Python before 3.13 raises this for a symlink loop
        raise EasVoError(f"--out {out}: its symbolic links form a loop; remove them or choose another path") from None
    except OSError as exc:
        raise EasVoError(f"--out {out}: cannot be resolved ({exc.strerror or exc})") from None


def check_writable_folder(out: str | Path) -> Path:
    """The absolute folder `out` (symlinks followed) if it is, or can be made, a writable folder
    other than the root; else a one-line error."""
    out = resolved_out(out)
    if out == Path(out.anchor):
        raise EasVoError(f"--out {out} is the root of the file system; choose a folder")
    if out.exists() and not out.is_dir():
        raise EasVoError(f"--out {out} is a file, not a folder")
    _check_writable(out)
    return out


#: How the files eas-vo writes begin, by kind: an existing --out is replaced only if it is one.
FILE_SIGNATURES = {
    "PNG image": re.compile(rb"\x89PNG\r\n\x1a\n"),
    "DBoW2 vocabulary": re.compile(rb"\d+ \d+ \d+ \d+\s"),
}


def check_output_file(out: str | Path, replace: bool) -> Path:
    """The absolute output file (symlinks followed), or a one-line error, before any work: a
    folder is refused, so is a place that cannot be written, and an existing file unless `replace`."""
    out = resolved_out(out)
    if out.is_dir():
        raise EasVoError(f"--out {out} is a folder; give the name of the file to write, e.g. {out / 'gallery.png'}")
    if out.exists() and not replace:
        raise EasVoError(f"--out {out} exists; choose another name or add --overwrite")
    _check_writable(out)
    return out


def refuse_foreign_file(out: Path, kind: str) -> None:
    """A one-line error when the existing file `out` does not begin as eas-vo's files of `kind`
    do (FILE_SIGNATURES): --overwrite never replaces a file of something else (a note, another
    tool's output), wherever it lies."""
    if not out.is_file():
        return
    with open(out, "rb") as f:
        start = f.read(64)
    if not FILE_SIGNATURES[kind].match(start):
        raise EasVoError(
            f"--out {out} exists and is no {kind}, so not a file eas-vo wrote: --overwrite replaces only "
            "those; choose another name"
        )


def _check_writable(out: Path) -> None:
    """A one-line error unless the nearest existing folder of `out` (itself, or its parent) can be written."""
    existing = next(p for p in [out, *out.parents] if p.exists() and p.is_dir())
    if not os.access(existing, os.W_OK | os.X_OK):
        raise EasVoError(f"--out {out}: {existing} is not writable")


def refuse_inputs(out: Path, inputs: list[tuple[str, str | Path | None]], out_is_file: bool = False) -> None:
    """A one-line error when writing `out` (resolved_out) would replace one of a command's
    `inputs` ((what, path or None): a dataset, a config, a calibration, ...): an output folder
    that is or holds an input, an output file that is one or lies inside one. A folder input
    counts with every file under it and where its links lead (an `events.txt` linked from
    elsewhere), and paths are compared both resolved and by (device, inode), which catches hard
    links and a folder mounted twice. Inputs that do not exist are left to their readers."""
    identities: dict[Path, tuple[int, int] | None] = {}

    def identity(path: Path) -> tuple[int, int] | None:
        if path not in identities:
            identities[path] = _identity(path)
        return identities[path]

    out_ids = {identity(p) for p in ([out, *out.parents] if out_is_file else [out])} - {None}
    for what, given in inputs:
        if given is None:
            continue
        top = Path(given).expanduser()
        for path, target in _input_files(top):
            named = f"{what} {given}" + (f" (its {path.relative_to(top)})" if path != top else "")
            if out_is_file and (out == target or out.is_relative_to(target) or identity(path) in out_ids):
                raise EasVoError(f"--out {out} is {named}, or inside it; writing there would replace it")
            if not out_is_file and (
                target.is_relative_to(out) or out_ids and any(identity(p) in out_ids for p in [target, *target.parents])
            ):
                raise EasVoError(f"--out {out} holds {named}; writing there would replace it")


def _identity(path: Path) -> tuple[int, int] | None:
    """(st_dev, st_ino) of what `path` names (links followed), or None if it cannot be reached."""
    try:
        st = path.stat()
    except (OSError, RuntimeError):
        return None
    return st.st_dev, st.st_ino


def _resolved_input(path: Path) -> Path | None:
    """`path` resolved, or None when it does not exist or its links loop (its reader says so)."""
    try:
        return path.resolve(strict=True)
    except (OSError, RuntimeError):
        return None


def _input_files(top: Path):
    """(path, where it resolves to) of `top` and, for a folder, of every file and link under it
    (links to folders not entered: their targets count as the links resolve); only links are
    resolved one by one, the rest lie where `top` resolves. What does not exist or loops is left out."""
    top_target = _resolved_input(top)
    if top_target is None:
        return
    yield top, top_target
    if top_target.is_dir():
        for root, dirs, files in os.walk(top):
            for name in [*dirs, *files]:
                path = Path(root) / name
                target = _resolved_input(path) if path.is_symlink() else top_target / path.relative_to(top)
                if target is not None:
                    yield path, target


def check_output_folder(out: str | Path, replace: bool) -> Path:
    """The absolute output folder (symlinks followed), or a one-line error, before any work:
    a file or the root is refused, so is a folder that cannot be written, and a non-empty one
    unless `replace`; even then only a folder holding nothing but the files its marker lists is
    replaced, never one holding someone's other files."""
    out = check_writable_folder(out)
    if out.is_dir() and any(out.iterdir()):
        if not replace:
            raise EasVoError(f"--out {out} is not empty; choose another folder or add --overwrite")
        foreign = _foreign_file(out)
        if foreign is not None:
            raise EasVoError(
                f"--out {out} holds {foreign}, which eas-vo did not write; it replaces only "
                "folders of its own outputs: move that away or choose another folder"
            )
    return out


def _foreign_file(folder: Path) -> str | None:
    """The first file in `folder` (relative path) that its marker does not list as eas-vo's own
    (every file, without a readable marker), or None."""
    try:
        listed = set((folder / OUTPUT_MARKER).read_text(encoding="utf-8").splitlines()[1:]) | {OUTPUT_MARKER}
    except (OSError, UnicodeDecodeError):
        listed = set()
    return next((name for name in _files_in(folder) if name not in listed), None)


def _files_in(folder: Path) -> list[str]:
    """Every file under `folder`, as sorted relative POSIX paths."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir())


#: The first line of the marker of a grid folder (compare, reproduce), written in place and
#: resumed: its cells' folders (each with its own marker) and its tables and figures are eas-vo's.
GRID_MARKER = "written by eas-vo compare or reproduce, which resume here (each cell's folder lists its own files):"


def check_grid_folder(out: str | Path) -> Path:
    """The absolute folder (check_writable_folder) compare or reproduce may write into: new,
    empty, or one they marked as their own (claim_grid_folder), which they resume; else a
    one-line error naming a file it holds."""
    out = check_writable_folder(out)
    if out.is_dir() and any(out.iterdir()) and not _is_grid_folder(out):
        held = next(iter(_files_in(out)), None) or next(out.iterdir()).name
        raise EasVoError(
            f"--out {out} holds {held} and is not an earlier compare's or reproduce's output, which "
            "they resume; they write only into a new or empty folder: choose another one"
        )
    return out


def claim_grid_folder(out: str | Path) -> Path:
    """check_grid_folder, then `out` made and marked as a grid folder before anything is written there."""
    out = check_grid_folder(out)
    if not _is_grid_folder(out):
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / OUTPUT_MARKER, GRID_MARKER + "\n")
    return out


@contextmanager
def removed_if_failed(out: Path):
    """Around a command's work into folder `out`: if `out` did not exist before and the work
    fails (an error or an interrupt) before writing anything there but the marker, `out` is
    removed, so a failed command leaves behind no folder it made."""
    made = not out.exists()
    try:
        yield out
    except BaseException:
        if made and out.is_dir() and {p.name for p in out.iterdir()} <= {OUTPUT_MARKER}:
            shutil.rmtree(out, ignore_errors=True)
        raise


def _is_grid_folder(folder: Path) -> bool:
    try:
        return (folder / OUTPUT_MARKER).read_text(encoding="utf-8").splitlines()[:1] == [GRID_MARKER]
    except (OSError, UnicodeDecodeError):
        return False


@contextmanager
def output_folder(out: str | Path, replace: bool = False, keep_partial: bool = True):
    """One writer per folder, and a folder that holds one whole run: lock `out` (a sibling
    `.NAME.lock` holding the writer's pid and start time; a lock whose process is gone is taken
    over), check it under the lock (check_output_folder), yield a fresh hidden sibling folder to
    write into, and when the block ends normally or (with `keep_partial`) by an interrupt (the
    partial outputs are then written) move it into place, replacing what `out` held. On any
    other error the new folder is dropped and `out` stays as it was (a write's error names its
    file under `out`, or `out` when it names none)."""
    out = resolved_out(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    lock = out.with_name(f".{out.name}.lock")
    acquire_lock(lock, out)
    staging = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        check_output_folder(out, replace)  # again, under the lock: another writer may have come first
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        try:
            yield staging
        except KeyboardInterrupt:
            if keep_partial:
                _move_into_place(staging, out)
            raise
        _move_into_place(staging, out)
    except OSError as exc:  # named as the user knows it: `out`, or its file, not the staging folder
        name_the_written(exc, out)
        if isinstance(exc.filename, str) and Path(exc.filename).is_relative_to(staging):
            exc.filename = str(out / Path(exc.filename).relative_to(staging))
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        lock.unlink(missing_ok=True)


def _move_into_place(staging: Path, out: Path) -> None:
    """Write the marker listing every file of `staging` (what a later --overwrite may replace),
    rename `staging` to `out`, the old `out` (if any) set aside first and then removed."""
    listing = ["written by eas-vo (--overwrite replaces only these):", *_files_in(staging)]
    (staging / OUTPUT_MARKER).write_text("".join(f"{line}\n" for line in listing))
    old = out.with_name(f".{out.name}.{os.getpid()}.old")
    if out.exists():
        os.replace(out, old)
    os.replace(staging, out)
    shutil.rmtree(old, ignore_errors=True)


@contextmanager
def added_file(folder: Path, name: str):
    """A temporary path (atomic_path) for the file `name` added to the finished output folder
    `folder`, written under the folder's writer's lock (output_folder's) and then listed in its
    marker, so that a later --overwrite replaces it as eas-vo's own (a folder without a marker
    is left without one). The temporary a killed writer left there is removed first."""
    lock = folder.with_name(f".{folder.name}.lock")
    acquire_lock(lock, folder)
    try:
        remove_stale_temporaries(folder, (name,))
        with atomic_path(folder / name) as tmp:
            yield tmp
        marker = folder / OUTPUT_MARKER
        if marker.is_file():
            lines = marker.read_text(encoding="utf-8").splitlines()
            if name not in lines[1:]:
                write_text_atomic(marker, "".join(f"{line}\n" for line in [*lines, name]))
    finally:
        lock.unlink(missing_ok=True)
