"""Event text files (`t x y p` per line) at speed, and their binary cache.

The first read streams the text in blocks through a compiled parser (two threads),
validates each block and appends it to a binary cache file; later reads map the
cache from disk. Memory stays bounded by the block size, so a text file larger
than memory can be converted, and the cached stream is then used window by window.

Cache file: 16-byte header (magic, event count) + packed EVENT_DTYPE records (13 B/event).
"""

from __future__ import annotations

import hashlib
import io
import json
import mmap
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


@numba.njit(cache=True, nogil=True, inline="always")
def _accept(t, x, y, p, last_t, width, height, tolerance_s):
    """Validate a row against the sensor and the previous time: (ok, t clamped if a small step back)."""
    if not np.isfinite(t) or x < 0 or x >= width or y < 0 or y >= height or p < -1 or p > 1:
        return False, t
    if t < last_t:
        if t < last_t - tolerance_s:
            return False, t
        return True, last_t
    return True, t


@numba.njit(cache=True, nogil=True, inline="always")
def _pack(out, n, t, x, y, p, scratch):
    """Write row n as a packed EVENT_DTYPE record (13 bytes, little-endian) into the bytes `out`."""
    scratch[0] = t
    t_bytes = scratch.view(np.uint8)
    o = 13 * n
    for b in range(8):
        out[o + b] = t_bytes[b]
    out[o + 8] = x & 0xFF
    out[o + 9] = x >> 8
    out[o + 10] = y & 0xFF
    out[o + 11] = y >> 8
    out[o + 12] = 1 if p > 0 else 0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _parse_and_pack(buf, pow10, width, height, tolerance_s, last_t, out):
    """Parse, validate and pack `t x y p` lines of `buf` (which ends with a newline: it stops
    every scan) into EVENT_DTYPE records in the bytes `out`, after a previous time `last_t`.

    Returns (rows, byte offset of the first line that is not in the plain form or not valid,
    or -1, newlines before it, first time, last time). A time is the nearest double to its
    decimal text (an exact integer mantissa over an exact power of ten).

    The digit loops are written out on purpose: factored into an inlined helper they ran
    at half the speed. The scan index is unsigned to spare numba's negative-index checks.
    """
    scratch = np.empty(1, np.float64)
    first_t = -np.inf
    n = 0
    i = np.uint64(0)
    one = np.uint64(1)
    lines = 0
    size = np.uint64(len(buf))
    while i < size:
        c = buf[i]
        while c == 32 or c == 9 or c == 13:
            i += one
            c = buf[i]
        if c == 10:
            i += one
            lines += 1
            continue
        start = i
        mant = 0
        nd = 0
        while 48 <= c <= 57:
            mant = mant * 10 + (c - 48)
            nd += 1
            i += one
            c = buf[i]
        dec = 0
        if c == 46:
            i += one
            c = buf[i]
            while 48 <= c <= 57:
                mant = mant * 10 + (c - 48)
                dec += 1
                i += one
                c = buf[i]
        if nd + dec == 0 or nd + dec > 15 or not (c == 32 or c == 9):
            return n, np.int64(start), lines, first_t, last_t
        x = y = p = 0
        for k in range(3):
            while c == 32 or c == 9:
                i += one
                c = buf[i]
            negative = False
            if k == 2 and c == 45:
                negative = True
                i += one
                c = buf[i]
            v = 0
            m = 0
            while 48 <= c <= 57:
                v = v * 10 + (c - 48)
                m += 1
                i += one
                c = buf[i]
            if m == 0 or m > 6:
                return n, np.int64(start), lines, first_t, last_t
            if k == 0:
                x = v
            elif k == 1:
                y = v
            else:
                p = -v if negative else v
        while c == 32 or c == 9 or c == 13:
            i += one
            c = buf[i]
        if c != 10:
            return n, np.int64(start), lines, first_t, last_t
        ok, t = _accept(mant / pow10[dec], x, y, p, last_t, width, height, tolerance_s)
        if not ok:
            return n, np.int64(start), lines, first_t, last_t
        if n == 0:
            first_t = t
        last_t = t
        _pack(out, n, t, x, y, p, scratch)
        n += 1
        i += one
        lines += 1
    return n, -1, lines, first_t, last_t


def _split_at_newline(buf: np.ndarray, parts: int) -> list[np.ndarray]:
    bounds = [0]
    for k in range(1, parts):
        guess = max(bounds[-1], len(buf) * k // parts)
        nl = np.flatnonzero(buf[guess : guess + (1 << 20)] == 10)
        bounds.append(guess + int(nl[0]) + 1 if len(nl) else bounds[-1])
    bounds.append(len(buf))
    return [buf[a:b] for a, b in zip(bounds, bounds[1:])]


def _terminated(piece: np.ndarray) -> np.ndarray:
    """The piece, ending with a newline (the compiled scans stop on it)."""
    if len(piece) and piece[-1] != 10:
        return np.concatenate([piece, np.array([10], np.uint8)])
    return piece


class BlockParser:
    """Parses, validates and packs blocks of lines in `threads` pieces at once, each piece as
    if it started the stream; the caller accepts a piece when its first time is not before
    the previous piece's last, and takes the sequential path otherwise.

    Packed records live in one of two alternating buffer sets that are reused (fresh ones
    would cost more in page faults than the parse): valid until the block after next.
    """

    def __init__(self, width: int, height: int, tolerance_s: float, threads: int = 2):
        self.limits = (width, height, tolerance_s)
        self.threads = threads
        self.pool = ThreadPoolExecutor(threads) if threads > 1 else None
        self.buffers: dict = {}
        self.calls = 0

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()

    def _buffer(self, key, rows: int) -> np.ndarray:
        if key not in self.buffers or len(self.buffers[key]) < rows:
            self.buffers[key] = np.empty(max(rows, 1024), EVENT_DTYPE)
        return self.buffers[key]

    def __call__(self, buf: np.ndarray) -> list[tuple]:
        """Per piece of `buf`, in order: (the piece, and if every line was plain and valid:
        (records, newlines, first time, last time), else None)."""
        pieces = [_terminated(p) for p in _split_at_newline(buf, self.threads if len(buf) > (1 << 20) else 1)]
        parity = self.calls % 2
        self.calls += 1

        def run(k):
            piece = pieces[k]
            out = self._buffer((parity, k), len(piece) // 8 + 1)  # a line has at least 8 bytes
            n, bad, lines, first_t, last_t = _parse_and_pack(piece, _POW10, *self.limits, -np.inf, out.view(np.uint8))
            return piece, (None if bad >= 0 else (out[:n], lines, first_t, last_t))

        return list(self.pool.map(run, range(len(pieces)))) if len(pieces) > 1 else [run(0)]


def parse_block(buf: np.ndarray, width: int = 65535, height: int = 65535, tolerance_s: float = np.inf) -> np.ndarray | None:
    """Plain, valid `t x y p` lines -> EVENT_DTYPE records (a copy), or None if any line is not."""
    parser = BlockParser(width, height, tolerance_s, threads=1)
    try:
        (_, result), = parser(buf)
    finally:
        parser.close()
    return None if result is None else result[0].copy()


def iter_blocks(fh: BinaryIO, block_bytes: int = BLOCK_BYTES) -> Iterator[np.ndarray]:
    """Blocks of whole lines (the last may lack its newline) as uint8 arrays.

    A regular file is memory-mapped (no copy; each block's pages are released once it is
    parsed, so a file larger than memory streams through). Other streams (zip members) are
    read chunk by chunk in the background, the line split by a chunk boundary coming as a
    small block of its own.
    """
    try:
        fileno = fh.fileno()
        size = os.fstat(fileno).st_size
    except (AttributeError, OSError, io.UnsupportedOperation):
        fileno = None
    if fileno is not None and size > 0:
        # Not closed explicitly: blocks handed out may outlive the loop; the mapping goes with them.
        mapped = mmap.mmap(fileno, 0, access=mmap.ACCESS_READ)
        mapped.madvise(mmap.MADV_SEQUENTIAL)
        text = np.frombuffer(mapped, np.uint8)
        page = mmap.PAGESIZE
        start = 0
        while start < size:
            end = min(start + block_bytes, size)
            if end < size:
                newline = mapped.rfind(b"\n", start, end)
                end = newline + 1 if newline >= start else (mapped.find(b"\n", end) + 1 or size)
            yield text[start:end]
            first_page = start - start % page
            mapped.madvise(mmap.MADV_DONTNEED, first_page, (end - first_page) // page * page)
            start = end
        return
    with ThreadPoolExecutor(1) as reader:
        future = reader.submit(fh.read, block_bytes)
        carry = b""
        while True:
            chunk = future.result()
            if not chunk:
                if carry:
                    yield np.frombuffer(carry, np.uint8)
                return
            future = reader.submit(fh.read, block_bytes)
            first = chunk.find(b"\n") + 1
            if first == 0:
                carry += chunk
                continue
            yield np.frombuffer(carry + chunk[:first], np.uint8)
            last = chunk.rfind(b"\n") + 1
            if last > first:
                yield np.frombuffer(chunk, np.uint8, last - first, first)
            carry = chunk[last:]


@numba.njit(cache=True, nogil=True)
def _check_and_pack(t, x, y, p, last_t, width, height, tolerance_s, out):
    """Validate parsed rows and pack them into the bytes `out`. Returns (index of the first
    row with any problem or -1, the last timestamp); rows before a problem are packed."""
    scratch = np.empty(1, np.float64)
    for i in range(len(t)):
        ok, ti = _accept(t[i], x[i], y[i], p[i], last_t, width, height, tolerance_s)
        if not ok:
            return i, last_t
        last_t = ti
        _pack(out, i, ti, x[i], y[i], p[i], scratch)
    return -1, last_t


class Validator:
    """Checks one block of parsed rows at a time, carrying the last timestamp across blocks."""

    def __init__(
        self, where: str, width: int, height: int, tolerance_s: float, lenient: bool, warnings: DataWarnings, unit: str = "line"
    ):
        self.where, self.width, self.height, self.unit = where, width, height, unit
        self.tolerance_s, self.lenient, self.warnings = tolerance_s, lenient, warnings
        self.last_t = -np.inf

    def __call__(self, t, x, y, p, line_of: Callable[[int], int]) -> np.ndarray:
        """EVENT_DTYPE records of the valid rows, in order (t may be clamped in place)."""
        t = np.ascontiguousarray(t, dtype=np.float64)
        events = np.empty(len(t), EVENT_DTYPE)
        bad, last_t = _check_and_pack(
            t, np.ascontiguousarray(x), np.ascontiguousarray(y), np.ascontiguousarray(p),
            self.last_t, self.width, self.height, self.tolerance_s, events.view(np.uint8),
        )
        if bad < 0:  # the common case: every row is valid
            self.last_t = last_t
            return events
        return self._filter(t, x, y, p, line_of)

    def _filter(self, t, x, y, p, line_of) -> np.ndarray:
        """Row-by-row verdicts. Strict: the earliest bad row raises, naming its first problem.
        Lenient: every bad row is dropped and counted once, under its first problem."""
        problems = [
            (~np.isfinite(t), "timestamp is not finite", lambda i: f"t = {t[i]}"),
            ((x < 0) | (x >= self.width) | (y < 0) | (y >= self.height),
             f"pixel outside the {self.width}x{self.height} sensor", lambda i: f"({x[i]}, {y[i]})"),
            (~np.isin(p, (0, 1, -1)), "polarity not 0/1 (or -1/1)", lambda i: f"p = {p[i]}"),
        ]
        keep = ~np.logical_or.reduce([bad for bad, _, _ in problems])
        # Small steps back in time (within the tolerance) are clamped; larger ones are problems.
        running = np.maximum.accumulate(np.concatenate([[self.last_t], np.where(keep, t, -np.inf)]))[:-1]
        problems.append((keep & (t < running - self.tolerance_s), "timestamp goes backwards",
                         lambda i: f"{t[i]:.9f} after {running[i]:.9f}"))
        first_problem = np.full(len(t), -1)
        for k in range(len(problems) - 1, -1, -1):
            first_problem[problems[k][0]] = k
        bad_rows = np.flatnonzero(first_problem >= 0)
        if len(bad_rows) and not self.lenient:
            i = int(bad_rows[0])
            _, what, describe = problems[first_problem[i]]
            raise DataError(self.where, f"{what}: {describe(i)}", line_of(i))
        for k, (_, what, _) in enumerate(problems):
            rows = np.flatnonzero(first_problem == k)
            if len(rows):
                self.warnings.add(self.where, what, f"{self.unit} {line_of(int(rows[0]))}", len(rows))
        keep = first_problem < 0
        t = np.maximum.accumulate(np.concatenate([[self.last_t], t[keep]]))[1:]
        if len(t):
            self.last_t = t[-1]
        events = np.empty(len(t), EVENT_DTYPE)
        events["t"], events["x"], events["y"], events["p"] = t, x[keep], y[keep], p[keep] > 0
        return events



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


def _sequential_piece(piece, first_line: int, validate: Validator, where: str, lenient: bool, warnings) -> tuple:
    """A piece the parallel pass could not take whole, in order: the compiled pass over each run
    of good lines, the line-by-line path (exact error, or counted drop) for each bad line.
    Returns (records, newlines)."""
    chunks, i, line = [], 0, first_line
    out = np.empty(len(piece) // 8 + 1, EVENT_DTYPE)
    while i < len(piece):
        rest = piece[i:]
        n, bad, lines, _, last_t = _parse_and_pack(rest, _POW10, validate.width, validate.height,
                                                   validate.tolerance_s, validate.last_t, out.view(np.uint8))
        chunks.append(out[:n].copy())
        validate.last_t = last_t
        line += lines
        if bad < 0:
            break
        end = bad + int(np.argmax(rest[bad:] == 10)) + 1
        columns, lines_of_rows, pending = _slow_rows(rest[bad:end].tobytes(), line, where, lenient, warnings)
        chunks.append(validate(*columns, lines_of_rows.__getitem__))
        if pending is not None:
            raise pending
        line += 1
        i += end
    return np.concatenate(chunks), line - first_line


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
    parser = BlockParser(width, height, tolerance_s)
    writer = ThreadPoolExecutor(1)  # writes overlap the parsing of the next block
    pending_write = None
    try:
        for block in iter_blocks(fh, block_bytes):
            records = []
            for piece, packed in parser(block):
                if packed is not None and packed[2] >= validate.last_t:  # packed in parallel, still valid
                    events, newlines, _, validate.last_t = packed
                else:
                    events, newlines = _sequential_piece(piece, first_line, validate, where, lenient, warnings)
                records.append(events.data)
                total += len(events)
                first_line += newlines
            if pending_write is not None:
                pending_write.result()
            pending_write = writer.submit(out.writelines, records)
        if pending_write is not None:
            pending_write.result()
    finally:
        parser.close()
        writer.shutdown()
    return total


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
    if (np.diff(events["t"]) < 0).any():
        raise ValueError("write_events_text needs events sorted by time")
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


def build_cache(path: Path, fill: Callable[[BinaryIO], int], max_events: int = 0) -> np.ndarray:
    """Write a cache file atomically: `fill(fh)` writes the records and returns their count.

    `max_events` > 0 reserves the file's blocks up front (fewer, faster writes on most file
    systems); the file is cut to its real size at the end.
    """
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            if max_events > 0 and hasattr(os, "posix_fallocate"):
                try:
                    os.posix_fallocate(fh.fileno(), 0, HEADER_BYTES + max_events * EVENT_DTYPE.itemsize)
                except OSError:
                    pass  # no space to reserve (or no support): plain writes still work
            fh.write(CACHE_MAGIC + bytes(8))
            count = fill(fh)
            fh.truncate(HEADER_BYTES + count * EVENT_DTYPE.itemsize)
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
    key: str, lenient: bool, warnings: DataWarnings, fill: Callable[[BinaryIO, DataWarnings], int], where: str,
    max_events: int = 0,
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
        events = build_cache(target, lambda out: fill(out, local), max_events)
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
    text_size: int | None = None,
) -> np.ndarray:
    """Events of a text source (`t x y p` lines, `text_size` bytes if known), through the cache."""

    def fill(out, local):
        with open_text() as fh:
            return convert_text_to_cache(fh, where, out, width, height, tolerance_s, lenient, local)

    key = cache_key("text", *identity, width, height, tolerance_s)
    size = text_size or 0  # a line is at least 8 bytes: at most size // 8 events
    return load_cached(key, lenient, warnings if warnings is not None else DataWarnings(), fill, where, size // 8 + 1 if size else 0)


def prime_text_cache(source: Path, events: np.ndarray, width: int, height: int, tolerance_s: float = 1e-6) -> None:
    """Store events already in memory as the cache of text file `source` (they must equal its parse)."""
    write_cache(cache_path(cache_key("text", *file_identity(source), width, height, tolerance_s)), events)
