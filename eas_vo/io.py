"""File I/O shared by datasets and the pipeline: numeric text tables, TUM trajectories,
atomic writes, folder names."""

from __future__ import annotations

import errno
import itertools
import json
import math
import os
import re
import shutil
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError, EasVoError


def cache_dir() -> Path:
    """User cache folder: $EAS_VO_CACHE_DIR, else $XDG_CACHE_HOME/eas-vo, else ~/.cache/eas-vo."""
    env = os.environ.get("EAS_VO_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "eas-vo"


#: The file in each cache folder saying what it holds (cache_folder, cache_usage).
CACHE_ABOUT = ".about"


def cache_folder(name: str, about: str) -> Path:
    """The cache folder's part `name` (created when possible), with a line saying what it
    holds and what clearing it costs (`eas-vo cache` shows it; rewritten when it differs)."""
    folder = cache_dir() / name
    line = folder / CACHE_ABOUT
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not line.is_file() or line.read_text(errors="replace") != about + "\n":
            write_text_atomic(line, about + "\n")
    except OSError:
        pass  # a read-only cache: whoever writes there says why
    return folder


@dataclass(frozen=True)
class CachePart:
    """One folder of the cache: its entries and bytes (hidden files, such as writes under way
    and CACHE_ABOUT, left out; links inside never followed), what it holds (its CACHE_ABOUT
    line, "" without one), and whether the part itself is a link to a folder elsewhere."""

    entries: int
    size: int
    about: str
    link: bool = False


def _visible(folder: Path) -> list[Path]:
    return [p for p in folder.iterdir() if not p.name.startswith(".")]


def cache_usage() -> dict[str, CachePart]:
    """Each folder of the cache folder (a link to a folder counts as one), by name."""
    root = cache_dir()
    if root.exists() and not root.is_dir():
        raise EasVoError(f"{root}: the cache folder (EAS_VO_CACHE_DIR) is not a folder")
    usage = {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []:
        entries = _visible(folder)
        files = [f for e in entries for f in ([e] if not e.is_dir() or e.is_symlink() else e.rglob("*"))
                 if f.is_file() and not f.is_symlink() and not f.name.startswith(".")]
        about = folder / CACHE_ABOUT
        usage[folder.name] = CachePart(len(entries), sum(f.lstat().st_size for f in files),
                                       about.read_text(errors="replace").strip() if about.is_file() else "",
                                       folder.is_symlink())
    return usage


def clear_cache(names: list[str]) -> dict[str, int]:
    """Empty the cache folders `names` (all checked first), leaving hidden files (writes under
    way, CACHE_ABOUT) and what links point to; the bytes freed by each. A folder that is a link
    is refused: its target is not the cache's to empty."""
    usage = cache_usage()
    unknown = [name for name in names if name not in usage]
    if unknown:
        raise EasVoError(f"cache {unknown[0]!r}: not in {cache_dir()} (there: {', '.join(usage) or 'nothing'})")
    linked = [name for name in names if usage[name].link]
    if linked:
        link = cache_dir() / linked[0]
        raise EasVoError(f"cache {linked[0]!r}: {link} is a link to {link.resolve()}, which eas-vo does not empty; "
                         "remove the link, or empty that folder yourself")
    for name in dict.fromkeys(names):
        for entry in _visible(cache_dir() / name):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
    return {name: usage[name].size for name in dict.fromkeys(names)}


# ----------------------------------------------------------------------------- atomic writes


def current_umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def silenced_stderr():
    """Send what C libraries write to file descriptor 2 to /dev/null for the block (libpng
    prints its own complaint about a damaged PNG; eas-vo's one error line says it instead)."""
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


#: The errors of a write (a full disk or quota, a file too large, a read-only or forbidden place,
#: a failing device), whose OSError names no file when `write` or `close` raised it.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO})


def name_the_written(exc: BaseException, path: Path) -> None:
    """Give a write's OSError that names no file the `path` being written (the CLI's one line
    says "No space left on device (PATH)"); any other exception is left as it is."""
    if isinstance(exc, OSError) and exc.filename is None and exc.errno in WRITE_ERRNOS:
        exc.filename = str(path)


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside `path`, `.NAME.PID.RANDOM.tmp`; on success rename it over
    `path` with the mode a plain `open` would have given it (0666 less the umask), else delete
    it (a killed writer's is left: remove_stale_temporaries). A write's error names `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        name_the_written(exc, path)
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_file(path: str | Path):
    """An open binary file to write, renamed over `path` on success (atomic_path's temporary).

    The temporary is opened write-only without truncating it (it is empty): on ext4, an
    open that truncates marks the file so that closing it writes all of it out at once (the
    file system's safeguard for files rewritten in place), which took ~100 ms per 250 MB of
    event cache on the close, with the caller waiting; opened read-write instead, Python's
    buffered file took 10-20 % longer over the writes of a cache."""
    with atomic_path(path) as tmp, os.fdopen(os.open(tmp, os.O_WRONLY), "wb") as fh:
        yield fh


def remove_stale_temporaries(folder: Path, names: tuple[str, ...]) -> None:
    """Delete the temporary files atomic_path left in `folder` for the files `names` (glob
    patterns, e.g. `fig3_*.png`) when the process that wrote them is gone (killed mid-write):
    those of a live writer, and every other file, stay."""
    for name in names:
        for tmp in folder.glob(f".{name}.*.tmp"):
            pid = tmp.name.removesuffix(".tmp").rsplit(".", 2)[-2]
            if tmp.is_file() and not tmp.is_symlink() and not (pid.isdigit() and _alive(int(pid))):
                tmp.unlink(missing_ok=True)


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
FILE_SIGNATURES = {"PNG image": re.compile(rb"\x89PNG\r\n\x1a\n"),
                   "DBoW2 vocabulary": re.compile(rb"\d+ \d+ \d+ \d+\s")}


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
        raise EasVoError(f"--out {out} exists and is no {kind}, so not a file eas-vo wrote: --overwrite replaces only "
                         "those; choose another name")


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
            if not out_is_file and (target.is_relative_to(out)
                                    or out_ids and any(identity(p) in out_ids for p in [target, *target.parents])):
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
            raise EasVoError(f"--out {out} holds {foreign}, which eas-vo did not write; it replaces only "
                             "folders of its own outputs: move that away or choose another folder")
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
        raise EasVoError(f"--out {out} holds {held} and is not an earlier compare's or reproduce's output, which "
                         "they resume; they write only into a new or empty folder: choose another one")
    return out


def claim_grid_folder(out: str | Path) -> Path:
    """check_grid_folder, then `out` made and marked as a grid folder before anything is written there."""
    out = check_grid_folder(out)
    if not _is_grid_folder(out):
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / OUTPUT_MARKER, GRID_MARKER + "\n")
    return out


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
    _acquire(lock, out)
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


def _acquire(lock: Path, out: Path) -> None:
    """Take `lock`: it appears whole, with this process's pid and start time already in it (a
    file of its own hard-linked to the lock's name), so a writer killed at any moment never
    leaves an empty lock that others must wait out."""
    mine = lock.with_name(f"{lock.name}.{os.getpid()}")
    mine.write_text(f"{os.getpid()} {_started(os.getpid()) or ''}\n")
    try:
        for _ in range(2):
            try:
                _link_or_create(mine, lock)
                return
            except FileExistsError:
                if _lock_is_held(lock):
                    raise EasVoError(f"{out} is being written by another eas-vo process (pid {_lock_owner(lock)[0] or '?'}); "
                                     "wait for it or choose another --out") from None
                lock.unlink(missing_ok=True)  # its writer is gone: a crash left it, and maybe a staging folder
                _remove_leftovers(out)
        raise EasVoError(f"{out}: could not take its lock {lock}")
    finally:
        mine.unlink(missing_ok=True)


def _link_or_create(mine: Path, lock: Path) -> None:
    """`lock` made a second name of `mine`; FileExistsError if it exists. On a file system
    without hard links, created and then written (a kill in between leaves it empty)."""
    try:
        os.link(mine, lock)
    except FileExistsError:
        raise
    except OSError:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        with os.fdopen(fd, "w") as fh:
            fh.write(mine.read_text())


def _remove_leftovers(out: Path) -> None:
    """Staging folders and lock files of writers that are gone."""
    for stale in [*out.parent.glob(f".{out.name}.*.tmp"), *out.parent.glob(f".{out.name}.lock.*")]:
        pid = stale.name.removesuffix(".tmp").rsplit(".", 1)[-1]
        if pid.isdigit() and _alive(int(pid)):
            continue
        if stale.is_dir():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            stale.unlink(missing_ok=True)


def _lock_owner(lock: Path) -> tuple[int, str | None]:
    """(pid, process start time or None) written in a lock; pid 0 if it holds none yet."""
    try:
        fields = lock.read_text().split()
        return int(fields[0]) if fields else 0, fields[1] if len(fields) > 1 else None
    except (OSError, ValueError):
        return 0, None


def _lock_is_held(lock: Path) -> bool:
    """A lock is held while its process lives (the same process: its pid and, where the system
    tells it, its start time); one without a pid yet (being written, or a crash between
    creating and writing it), or without the start time the system gives (not written by
    eas-vo), for 10 s after it was made."""
    pid, started = _lock_owner(lock)
    if pid and _alive(pid):
        now = _started(pid)
        if now is None or started == now:
            return True
        if started is not None:  # the pid lives, but it is another process now
            return False
    elif pid:
        return False
    try:  # no pid, or a pid without the start time this system gives: trusted only while young
        return time.time() - lock.stat().st_mtime < 10.0
    except OSError:
        return False  # gone meanwhile: try again


def _started(pid: int) -> str | None:
    """When process `pid` started (clock ticks since boot, Linux /proc), or None if unknown:
    a pid reused by another process has another start time."""
    fields = _proc_stat(pid)
    return fields[19] if fields and len(fields) > 19 else None


def _proc_stat(pid: int) -> list[str] | None:
    """The fields of /proc/PID/stat after the command name (state first), or None off Linux or
    once the process is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rindex(")") + 2:].split()
    except (OSError, ValueError):
        return None


def _alive(pid: int) -> bool:
    """Whether process `pid` runs: it exists and (where /proc tells) is not a zombie, as a
    killed writer stays until its new parent reaps it (in containers, maybe never)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    fields = _proc_stat(pid)
    return not fields or fields[0] != "Z"


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


def json_text(obj) -> str:
    """Strict JSON (RFC 8259), indented: NaN and infinities, which it cannot hold, become null."""

    def finite(value):
        if isinstance(value, float) and not math.isfinite(value):
            return None
        if isinstance(value, dict):
            return {k: finite(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [finite(v) for v in value]
        return value

    return json.dumps(finite(obj), indent=2, allow_nan=False) + "\n"


def write_text_atomic(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)



def markdown_cell(text: str) -> str:
    """`text` as one cell of a Markdown table: each run of white space or control characters
    (a newline too) made one space, and `|` escaped, so the cell can end neither its row nor itself."""
    return re.sub(r"[\s\x00-\x1f\x7f]+", " ", text).strip().replace("|", "\\|")


def figure_text(value: float, decimals: int) -> str:
    """`value` with `decimals` decimals, or in scientific notation (`2.079e+155`) where that
    would print more than six integer digits: every figure short enough to read."""
    if math.isfinite(value) and abs(value) >= 1e6:
        return f"{value:.{max(decimals, 1)}e}"
    return f"{value:.{decimals}f}"


def slug(text: str) -> str:
    """A file-name-safe name for a dataset spec, path or label: its last path component with
    every run of characters other than letters, digits and `._=-` replaced by `-`."""
    return re.sub(r"[^A-Za-z0-9._=-]+", "-", Path(text.rstrip("/")).name or text).strip("-")


# ----------------------------------------------------------------------------- text tables

#: The UTF-8 byte-order mark some editors (Windows Notepad, for one) write at a text file's start.
UTF8_BOM = b"\xef\xbb\xbf"


def text_bytes(data: bytes) -> bytes:
    """A text input's bytes without a leading byte-order mark, which every text reader calls
    first (tables, calibrations, frame and event lists, registries). Line ends need no such
    care: the readers split on `\\n` and strip each line, so a CRLF file reads as an LF one."""
    return data.removeprefix(UTF8_BOM)



def clock_time(t_s: float, origin_ns: int = 0) -> str:
    """A time written to a file: `t_s` [s] after the clock origin `origin_ns` [ns]
    (Dataset.clock_origin_ns), as seconds with 9 decimals, summed in integer nanoseconds so that
    a Unix-time clock keeps every digit (float64 at 1.7e9 s keeps only about 0.24 us)."""
    if origin_ns == 0:
        return f"{t_s:.9f}"
    ns = origin_ns + round(float(t_s) * 1e9)
    whole, frac = divmod(abs(ns), 1_000_000_000)
    return f"{'-' if ns < 0 else ''}{whole}.{frac:09d}"


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A TUM trajectory `t tx ty tz qx qy qz qw` -> (t [s], p [m] (N, 3), q_xyzw (N, 4))."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns, found {rows.shape[1]}")
    return rows[:, 0], rows[:, 1:4], rows[:, 4:8]


def read_table(path: str | Path, ncols: int, what: str) -> np.ndarray:
    """A whitespace-separated numeric text file -> float64 array (N, ncols); see `parse_table`."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(path, f"cannot read: {exc.strerror or exc}") from None
    return parse_table(data, str(path), ncols, what)


def parse_table(data: bytes, where: str, ncols: int, what: str) -> np.ndarray:
    """Whitespace-separated numeric text -> float64 array (N, ncols).

    A fast C parse; on any irregularity a line-by-line scan names the first bad line.
    Lines starting with '#' are comments. `what` describes one row in messages.
    """
    data = text_bytes(data)
    if b"#" not in data:
        try:
            values = np.fromstring(data, sep=" ")  # text mode is supported, only binary mode is deprecated
        except ValueError:
            values = None
        if values is not None and values.size % ncols == 0 and np.isfinite(values).all():
            table = values.reshape(-1, ncols)
            if len(table) == _count_lines(data):
                return table
    return _parse_table_slow(where, data, ncols, what)


def data_line(data: bytes, row: int) -> int:
    """The file line (from 1) of data row `row` (from 0) of a table, blank and comment lines
    skipped as parse_table skips them."""
    return next(itertools.islice(_data_lines(data), row, None), (row + 1, b""))[0]


def _data_lines(data: bytes):
    """(file line from 1, stripped text) of each line of a table that is neither blank nor a `#` comment."""
    for lineno, line in enumerate(data.split(b"\n"), start=1):
        text = line.strip()
        if text and not text.startswith(b"#"):
            yield lineno, text


def _count_lines(data: bytes) -> int:
    n = data.count(b"\n")
    return n + 1 if data and not data.endswith(b"\n") else n


def _parse_table_slow(path: str, data: bytes, ncols: int, what: str) -> np.ndarray:
    rows = []
    for lineno, text in _data_lines(data):
        parts = text.split()
        if len(parts) != ncols:
            raise DataError(path, f"expected {ncols} columns ({what}), found {len(parts)}", lineno)
        try:
            row = [float(p) for p in parts]
        except ValueError:
            raise DataError(path, f"not a number in {text[:60].decode(errors='replace')!r}", lineno) from None
        if not all(np.isfinite(row)):
            raise DataError(path, "NaN or infinite value", lineno)
        rows.append(row)
    return np.array(rows, dtype=float).reshape(-1, ncols)
