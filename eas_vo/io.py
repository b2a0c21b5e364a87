"""File I/O shared by datasets and the pipeline: numeric text tables, the event
cache, fast event text writing and atomic writes."""

from __future__ import annotations

import hashlib
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError
from eas_vo.types import EVENT_DTYPE

CACHE_FORMAT_VERSION = 1


def cache_dir() -> Path:
    """User cache folder: $EAS_VO_CACHE_DIR, else $XDG_CACHE_HOME/eas-vo, else ~/.cache/eas-vo."""
    env = os.environ.get("EAS_VO_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "eas-vo"


# ----------------------------------------------------------------------------- atomic writes


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside `path`; on success rename it over `path`, else delete it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


# ----------------------------------------------------------------------------- text tables


def read_table(path: str | Path, ncols: int, what: str) -> np.ndarray:
    """Whitespace-separated numeric table -> float64 array (N, ncols).

    A fast C parse; on any irregularity a line-by-line scan names the first bad line.
    Lines starting with '#' are comments. `what` describes one row in messages.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(path, f"cannot read: {exc.strerror or exc}") from None
    if b"#" not in data:
        try:
            values = np.fromstring(data, sep=" ")  # noqa: NPY201 (text mode is supported)
        except ValueError:
            values = None
        if values is not None and values.size % ncols == 0 and np.isfinite(values).all():
            table = values.reshape(-1, ncols)
            if len(table) == _count_lines(data):
                return table
    return _read_table_slow(path, data, ncols, what)


def _count_lines(data: bytes) -> int:
    n = data.count(b"\n")
    return n + 1 if data and not data.endswith(b"\n") else n


def _read_table_slow(path: Path, data: bytes, ncols: int, what: str) -> np.ndarray:
    rows = []
    for lineno, line in enumerate(data.split(b"\n"), start=1):
        text = line.strip()
        if not text or text.startswith(b"#"):
            continue
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


# ----------------------------------------------------------------------------- events


def parse_events_text(path: Path, width: int, height: int) -> np.ndarray:
    """Parse and validate an ECD `events.txt` (`t x y p` per line) into EVENT_DTYPE."""
    table = read_table(path, 4, "t x y p")
    t, x, y, p = table.T
    bad = (x < 0) | (x >= width) | (y < 0) | (y >= height) | (x != np.floor(x)) | (y != np.floor(y))
    if bad.any():
        i = int(np.argmax(bad))
        raise DataError(path, f"pixel ({x[i]:g}, {y[i]:g}) outside the {width}x{height} sensor", i + 1)
    bad = ~np.isin(p, (0, 1, -1))
    if bad.any():
        i = int(np.argmax(bad))
        raise DataError(path, f"polarity {p[i]:g} is not 0/1 (or -1/1)", i + 1)
    backwards = np.flatnonzero(np.diff(t) < 0)
    if len(backwards):
        i = int(backwards[0]) + 1
        raise DataError(path, f"timestamp {t[i]:.9f} goes back from {t[i - 1]:.9f}", i + 1)
    events = np.empty(len(t), dtype=EVENT_DTYPE)
    events["t"], events["x"], events["y"] = t, x, y
    events["p"] = p > 0
    return events


def event_cache_path(source: Path) -> Path:
    """Cache file for `source`, keyed on its identity (device, inode), size and modification time,
    so that it survives the folder being renamed but not the file being changed."""
    st = source.stat()
    key = f"{st.st_dev}|{st.st_ino}|{st.st_size}|{st.st_mtime_ns}|{CACHE_FORMAT_VERSION}"
    return cache_dir() / "events" / (hashlib.sha1(key.encode()).hexdigest() + ".npy")


def load_events(path: str | Path, width: int, height: int) -> np.ndarray:
    """Events of an `events.txt`, memory-mapped from a binary cache built on first use."""
    path = Path(path)
    if not path.exists():
        raise DataError(path, "file not found")
    cached = event_cache_path(path)
    if cached.exists():
        try:
            events = np.load(cached, mmap_mode="r")
            if events.dtype == EVENT_DTYPE:
                return events
        except (OSError, ValueError):
            pass  # a damaged cache is rebuilt below
    events = parse_events_text(path, width, height)
    store_event_cache(path, events)
    return events


def store_event_cache(source: Path, events: np.ndarray) -> None:
    """Write the binary cache for `source` (best effort: a read-only cache is not an error)."""
    try:
        with atomic_path(event_cache_path(source)) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, np.ascontiguousarray(events, dtype=EVENT_DTYPE))
    except OSError:
        pass


def _ascii_digits(values: np.ndarray, width: int, pad: bool) -> np.ndarray:
    """Non-negative ints -> (N, width) ASCII digits; leading zeros -> 0 bytes unless `pad`."""
    out = np.empty((len(values), width), dtype=np.uint8)
    v = values.astype(np.int64)
    for k in range(width - 1, -1, -1):
        out[:, k] = 48 + v % 10
        v //= 10
    if not pad:
        ndigits = np.maximum(1, np.floor(np.log10(np.maximum(values, 1))).astype(int) + 1)
        out[np.arange(width)[None, :] < (width - ndigits)[:, None]] = 0
    return out


def format_events(events: np.ndarray) -> bytes:
    """EVENT_DTYPE -> ECD text lines `t x y p` (t with 9 decimals), vectorised."""
    n = len(events)
    if n == 0:
        return b""
    t_ns = np.round(events["t"] * 1e9).astype(np.int64)
    sec, frac = np.divmod(t_ns, 1_000_000_000)
    int_width = max(1, len(str(int(sec.max()))))
    sp = np.full((n, 1), 32, np.uint8)
    row = np.hstack(
        [
            _ascii_digits(sec, int_width, pad=False),
            np.full((n, 1), 46, np.uint8),
            _ascii_digits(frac, 9, pad=True),
            sp,
            _ascii_digits(events["x"], 5, pad=False),
            sp,
            _ascii_digits(events["y"], 5, pad=False),
            sp,
            48 + (events["p"] > 0).astype(np.uint8)[:, None],
            np.full((n, 1), 10, np.uint8),
        ]
    )
    flat = row.ravel()
    return flat[flat != 0].tobytes()


def write_events_text(path: str | Path, events: np.ndarray, chunk: int = 1_000_000) -> None:
    """Write events as ECD `events.txt` atomically, and prime the binary cache.

    The cache holds the times as the text will parse back (rounded to 1 ns).
    """
    path = Path(path)
    events = np.array(events, dtype=EVENT_DTYPE)
    events["t"] = np.round(events["t"] * 1e9) / 1e9
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            for start in range(0, len(events), chunk):
                fh.write(format_events(events[start : start + chunk]))
    store_event_cache(path, events)
