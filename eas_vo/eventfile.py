"""Event text files (`t x y p` per line) at speed, and their binary cache.

The first read streams the text in blocks through a compiled parser (two threads),
validates each block and appends it to a binary cache file; later reads map the
cache from disk. Memory stays bounded by the block size, so a text file larger
than memory can be converted, and the cached stream is then used window by window.

Cache file: 16-byte header (magic, event count) + packed EVENT_DTYPE records (13 B/event).
"""

from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Callable, Iterator

import numba
import numpy as np

from eas_vo.errors import DataError
from eas_vo.io import atomic_path, cache_dir
from eas_vo.types import EVENT_DTYPE

CACHE_MAGIC = b"EASVOEV1"
HEADER_BYTES = 16
BLOCK_BYTES = 64 << 20
_POW10 = 10.0 ** np.arange(19)


# ----------------------------------------------------------------------------- warnings


@dataclass
class DataWarnings:
    """Problems tolerated under `--lenient`, counted per file and kind, with the first place."""

    counts: dict = field(default_factory=dict)
    first: dict = field(default_factory=dict)

    def add(self, where: str, what: str, first_at, n: int = 1) -> None:
        key = (where, what)
        self.counts[key] = self.counts.get(key, 0) + n
        self.first.setdefault(key, first_at)

    def merge(self, other: "DataWarnings") -> None:
        for (where, what), n in other.counts.items():
            self.add(where, what, other.first[(where, what)], n)

    def lines(self) -> list[str]:
        return [f"{where}: {n} dropped: {what} (first at {self.first[(where, what)]})" for (where, what), n in self.counts.items()]

    def to_json(self) -> str:
        return json.dumps([[w, k, self.first[(w, k)], n] for (w, k), n in self.counts.items()])

    @classmethod
    def from_json(cls, text: str) -> "DataWarnings":
        out = cls()
        for where, what, first_at, n in json.loads(text):
            out.add(where, what, first_at, n)
        return out


# ----------------------------------------------------------------------------- compiled parser


@numba.njit(cache=True, nogil=True)
def _parse_block(buf, pow10, out_t, out_x, out_y, out_p):
    """Parse `t x y p` lines of `buf` (uint8) into the output columns. Returns (rows parsed,
    byte offset of the first line not in that plain form, or -1). A time is the nearest
    double to its decimal text (an exact integer mantissa over an exact power of ten)."""
    n = 0
    i = 0
    size = len(buf)
    while i < size:
        while i < size and (buf[i] == 32 or buf[i] == 9 or buf[i] == 13):
            i += 1
        if i >= size:
            break
        if buf[i] == 10:
            i += 1
            continue
        start = i
        mantissa = 0
        digits = 0
        while i < size and 48 <= buf[i] <= 57:
            mantissa = mantissa * 10 + (buf[i] - 48)
            digits += 1
            i += 1
        decimals = 0
        if i < size and buf[i] == 46:
            i += 1
            while i < size and 48 <= buf[i] <= 57:
                mantissa = mantissa * 10 + (buf[i] - 48)
                digits += 1
                decimals += 1
                i += 1
        if digits == 0 or digits > 15 or i >= size or not (buf[i] == 32 or buf[i] == 9):
            return n, start
        ints = np.zeros(3, np.int64)
        ok = True
        for k in range(3):
            while i < size and (buf[i] == 32 or buf[i] == 9):
                i += 1
            negative = False
            if k == 2 and i < size and buf[i] == 45:
                negative = True
                i += 1
            value = 0
            count = 0
            while i < size and 48 <= buf[i] <= 57 and count < 7:
                value = value * 10 + (buf[i] - 48)
                count += 1
                i += 1
            if count == 0 or count == 7:
                ok = False
                break
            ints[k] = -value if negative else value
        while i < size and (buf[i] == 32 or buf[i] == 9 or buf[i] == 13):
            i += 1
        if not ok or (i < size and buf[i] != 10):
            return n, start
        out_t[n] = mantissa / pow10[decimals]
        out_x[n] = ints[0]
        out_y[n] = ints[1]
        out_p[n] = ints[2]
        n += 1
        i += 1
    return n, -1


def _split_at_newline(buf: np.ndarray, parts: int) -> list[np.ndarray]:
    bounds = [0]
    for k in range(1, parts):
        guess = max(bounds[-1], len(buf) * k // parts)
        nl = np.flatnonzero(buf[guess : guess + (1 << 20)] == 10)
        bounds.append(guess + int(nl[0]) + 1 if len(nl) else bounds[-1])
    bounds.append(len(buf))
    return [buf[a:b] for a, b in zip(bounds, bounds[1:])]


def parse_block(buf: np.ndarray, pool: ThreadPoolExecutor | None = None):
    """Parse the lines of `buf` (in two threads when a pool is given) into (t, x, y, p),
    or None if any line is not in the plain `t x y p` form (the caller then goes slowly)."""
    pieces = _split_at_newline(buf, 2 if pool is not None and len(buf) > (1 << 20) else 1)

    def run(piece):
        n_max = int(np.count_nonzero(piece == 10)) + 1
        columns = (np.empty(n_max, np.float64), *(np.empty(n_max, np.int64) for _ in range(3)))
        n, bad = _parse_block(piece, _POW10, *columns)
        return None if bad >= 0 else [c[:n] for c in columns]

    results = list(pool.map(run, pieces)) if len(pieces) > 1 else [run(pieces[0])]
    if any(r is None for r in results):
        return None
    return [np.concatenate([r[k] for r in results]) for k in range(4)]


# ----------------------------------------------------------------------------- streaming conversion


def iter_blocks(fh: BinaryIO, block_bytes: int = BLOCK_BYTES) -> Iterator[bytes]:
    """Blocks of whole lines (the last may lack a final newline)."""
    carry = b""
    while True:
        chunk = fh.read(block_bytes)
        if not chunk:
            if carry:
                yield carry
            return
        data = carry + chunk
        cut = data.rfind(b"\n") + 1
        if cut == 0:
            carry = data
            continue
        carry = data[cut:]
        yield data[:cut]


class Validator:
    """Checks one block of parsed rows at a time, carrying the last timestamp across blocks."""

    def __init__(
        self, where: str, width: int, height: int, tolerance_s: float, lenient: bool, warnings: DataWarnings, unit: str = "line"
    ):
        self.where, self.width, self.height, self.unit = where, width, height, unit
        self.tolerance_s, self.lenient, self.warnings = tolerance_s, lenient, warnings
        self.last_t = -np.inf

    def __call__(self, t, x, y, p, line_of: Callable[[int], int]) -> np.ndarray:
        keep = np.ones(len(t), bool)
        keep &= self._check(~np.isfinite(t), "timestamp is not finite", line_of, lambda i: f"t = {t[i]}")
        outside = (x < 0) | (x >= self.width) | (y < 0) | (y >= self.height)
        keep &= self._check(outside, f"pixel outside the {self.width}x{self.height} sensor", line_of, lambda i: f"({x[i]}, {y[i]})")
        keep &= self._check(~np.isin(p, (0, 1, -1)), "polarity not 0/1 (or -1/1)", line_of, lambda i: f"p = {p[i]}")
        # Small steps back in time (within the tolerance) are clamped; larger ones are errors.
        running = np.maximum.accumulate(np.concatenate([[self.last_t], np.where(keep, t, -np.inf)]))[:-1]
        back = keep & (t < running - self.tolerance_s)
        keep &= self._check(back, "timestamp goes backwards", line_of, lambda i: f"{t[i]:.9f} after {running[i]:.9f}")
        t = np.maximum.accumulate(np.concatenate([[self.last_t], t[keep]]))[1:]
        if len(t):
            self.last_t = t[-1]
        events = np.empty(len(t), EVENT_DTYPE)
        events["t"], events["x"], events["y"], events["p"] = t, x[keep], y[keep], p[keep] > 0
        return events

    def _check(self, bad, what: str, line_of, describe) -> np.ndarray:
        """`~bad`, after a DataError (strict) or a counted warning (lenient) for any bad row."""
        if not bad.any():
            return ~bad
        i = int(np.argmax(bad))
        if not self.lenient:
            raise DataError(self.where, f"{what}: {describe(i)}", line_of(i))
        self.warnings.add(self.where, what, f"{self.unit} {line_of(i)}", int(bad.sum()))
        return ~bad


def _row_lines(buf: bytes, first_line: int) -> Callable[[int], int]:
    """Row index within a block -> 1-based line number in the file (blank lines skipped)."""

    def line_of(row: int) -> int:
        count = -1
        for k, line in enumerate(buf.split(b"\n")):
            if line.strip():
                count += 1
                if count == row:
                    return first_line + k
        return first_line

    return line_of


def _slow_rows(block: bytes, first_line: int, where: str, lenient: bool, warnings: DataWarnings):
    """Line-by-line parse of a block the fast parser rejected. Lenient: skips and counts bad
    lines. Strict: stops at the first and returns its error with the rows before it, so that
    an earlier invalid event can still be reported first."""
    rows, lines, pending = [], [], None
    for k, raw in enumerate(block.split(b"\n")):
        text = raw.strip()
        if not text:
            continue
        parts = text.split()
        problem = None
        if len(parts) != 4:
            problem = f"expected 4 columns (t x y p), found {len(parts)}"
        else:
            try:
                row = [float(v) for v in parts]
                if any(v != int(v) for v in row[1:]):
                    problem = "pixel coordinates and polarity must be integers"
            except (ValueError, OverflowError):
                problem = f"not a number in {text[:60].decode(errors='replace')!r}"
        if problem:
            if not lenient:
                pending = DataError(where, problem, first_line + k)
                break
            warnings.add(where, "malformed line", f"line {first_line + k}")
            continue
        rows.append(row)
        lines.append(first_line + k)
    table = np.array(rows, dtype=float).reshape(-1, 4)
    columns = table[:, 0], *(table[:, k].astype(np.int64) for k in (1, 2, 3))
    return columns, lines, pending


def convert_text_to_cache(
    fh: BinaryIO,
    where: str,
    out: BinaryIO,
    width: int,
    height: int,
    tolerance_s: float = 1e-6,
    lenient: bool = False,
    warnings: DataWarnings | None = None,
    block_bytes: int = BLOCK_BYTES,
) -> int:
    """Stream event text from `fh` into cache records written to `out`; returns the event count."""
    warnings = warnings if warnings is not None else DataWarnings()
    validate = Validator(where, width, height, tolerance_s, lenient, warnings)
    total, first_line = 0, 1
    with ThreadPoolExecutor(2) as pool:
        for block in iter_blocks(fh, block_bytes):
            buf = np.frombuffer(block, np.uint8)
            columns, pending = parse_block(buf, pool), None
            if columns is None:
                columns, lines, pending = _slow_rows(block, first_line, where, lenient, warnings)
                line_of = lines.__getitem__
            else:
                line_of = _row_lines(block, first_line)
            events = validate(*columns, line_of)
            if pending is not None:
                raise pending
            out.write(events.tobytes())
            total += len(events)
            first_line += block.count(b"\n")
    return total


# ----------------------------------------------------------------------------- writing


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


def write_events_text(path: str | Path, events: np.ndarray, width: int, height: int, chunk: int = 1_000_000) -> None:
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
    prime_text_cache(path, events, width, height)


# ----------------------------------------------------------------------------- cache


def cache_key(*parts) -> str:
    return hashlib.sha1("|".join(map(str, parts)).encode()).hexdigest()


def file_identity(path: Path) -> tuple:
    """What makes a file's content unique for the cache: device, inode, size, modification time."""
    st = path.stat()
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def cache_path(key: str) -> Path:
    return cache_dir() / "events" / f"{key}.ev"


def open_cache(path: Path) -> np.ndarray | None:
    """Memory-map a cache file; None if it is absent or damaged."""
    try:
        with open(path, "rb") as fh:
            header = fh.read(HEADER_BYTES)
        if len(header) != HEADER_BYTES or header[:8] != CACHE_MAGIC:
            return None
        count = int(np.frombuffer(header[8:], np.uint64)[0])
        if path.stat().st_size != HEADER_BYTES + count * EVENT_DTYPE.itemsize:
            return None
    except OSError:
        return None
    if count == 0:
        return np.empty(0, EVENT_DTYPE)
    return np.memmap(path, dtype=EVENT_DTYPE, mode="r", offset=HEADER_BYTES, shape=(count,))


def build_cache(path: Path, fill: Callable[[BinaryIO], int]) -> np.ndarray:
    """Write a cache file atomically: `fill(fh)` writes the records and returns their count."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(CACHE_MAGIC + bytes(8))
            count = fill(fh)
            fh.seek(8)
            fh.write(np.uint64(count).tobytes())
    return open_cache(path)


def write_cache(path: Path, events: np.ndarray) -> np.ndarray:
    """Cache an in-memory event array (e.g. decoded from a bag)."""

    def fill(fh):
        fh.write(np.ascontiguousarray(events, dtype=EVENT_DTYPE).tobytes())
        return len(events)

    return build_cache(path, fill)


def load_cached(
    key: str, lenient: bool, warnings: DataWarnings, fill: Callable[[BinaryIO, DataWarnings], int], where: str
) -> np.ndarray:
    """The event stream cached under `key`, built by `fill(out, warnings)` when absent.

    A clean stream has one cache whatever the mode. A lenient build that dropped data
    is cached apart, with its warnings beside it, so they are reported on every use
    and a strict read never gets it.
    """
    strict = cache_path(key)
    tolerant = strict.with_name(strict.stem + "-lenient.ev")
    for path in (strict, tolerant) if lenient else (strict,):
        cached = open_cache(path)
        if cached is not None:
            side = path.with_suffix(".warnings")
            if side.exists():
                warnings.merge(DataWarnings.from_json(side.read_text()))
            return cached
    local = DataWarnings()
    target = tolerant if lenient else strict
    try:
        events = build_cache(target, lambda out: fill(out, local))
    except OSError as exc:
        raise DataError(where, f"cannot read or cache events ({exc})") from None
    if local.counts:
        from eas_vo.io import write_text_atomic

        write_text_atomic(target.with_suffix(".warnings"), local.to_json())
    elif target is tolerant:
        os.replace(tolerant, strict)
        events = open_cache(strict)
    warnings.merge(local)
    return events


def load_event_text(
    open_text: Callable[[], BinaryIO],
    identity: tuple,
    where: str,
    width: int,
    height: int,
    tolerance_s: float = 1e-6,
    lenient: bool = False,
    warnings: DataWarnings | None = None,
) -> np.ndarray:
    """Events of a text source (`t x y p` lines), through the cache."""

    def fill(out, local):
        with open_text() as fh:
            return convert_text_to_cache(fh, where, out, width, height, tolerance_s, lenient, local)

    key = cache_key("text", *identity, width, height, tolerance_s)
    return load_cached(key, lenient, warnings if warnings is not None else DataWarnings(), fill, where)


def prime_text_cache(source: Path, events: np.ndarray, width: int, height: int, tolerance_s: float = 1e-6) -> None:
    """Store events already in memory as the cache of text file `source` (they must equal its parse)."""
    write_cache(cache_path(cache_key("text", *file_identity(source), width, height, tolerance_s)), events)
