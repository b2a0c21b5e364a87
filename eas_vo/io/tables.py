"""Numeric text tables: the fast parse with a line-by-line fallback that names the bad line,
times that must increase, and times written back with every digit of a Unix-time clock."""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError, DataWarnings

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


def row_number(row: int) -> int:
    """A table row's number as messages name it when no file line is known: from 1."""
    return row + 1


def check_increasing(
    where: str, t: np.ndarray, line_of=row_number, warnings: DataWarnings | None = None, row_word: str = "line"
) -> np.ndarray:
    """The indices of the rows to keep of a series whose time [s] must increase; `line_of(row)`
    turns a row index into what messages name (a file line; default: the row from 1), and
    `row_word` says what that is in a warning ("line", "message").

    A time that goes back is a DataError naming its row. A time equal to the previous one (a
    bag's IMU often repeats a stamp) is one too, unless `warnings` (--lenient) is given: then
    the repeating rows are dropped, the first kept, and counted there."""
    step = np.diff(t)
    back = np.flatnonzero(step < 0)
    if len(back):
        i = int(back[0]) + 1
        raise DataError(where, f"timestamp {t[i]:.9f} does not increase (previous {t[i - 1]:.9f})", line_of(i))
    repeated = np.flatnonzero(step == 0) + 1
    if len(repeated) and warnings is None:
        i = int(repeated[0])
        raise DataError(
            where,
            f"timestamp {t[i]:.9f} repeats the previous row's ({len(repeated)} such row(s); --lenient drops them)",
            line_of(i),
        )
    if len(repeated):
        warnings.add(where, "repeated timestamp", f"{row_word} {line_of(int(repeated[0]))}", len(repeated))
    return np.flatnonzero(np.concatenate([[True], step > 0])) if len(t) else np.arange(0)


def timed_table(
    data: bytes, where: str, ncols: int, what: str, warnings: DataWarnings | None = None
) -> tuple[np.ndarray, Callable[[int], int]]:
    """The rows of a whitespace table (`what` describes one; `#` comments) whose first column, a
    time [s], increases (with `warnings`, --lenient: rows repeating a time dropped, check_increasing),
    and row index -> file line; at least 2 rows (to interpolate between)."""
    table = parse_table(data, where, ncols, what)
    if len(table) < 2:
        raise DataError(
            where, f"holds {len(table)} row(s) of '{what}'; at least 2 are needed to interpolate (or remove the file)"
        )
    keep = check_increasing(where, table[:, 0], functools.partial(data_line, data), warnings)
    return table[keep], lambda row: data_line(data, int(keep[row]))
