"""Events held as rows of numbers (MVSEC's HDF5 `x y t p` float64 array, for one), checked
and packed into EVENT_DTYPE records one block at a time: pixel and polarity whole numbers,
then the Validator's checks (pixel on the sensor, time finite and not going back), the last
time carried from block to block. Rows are named by their index in the table (from 0).
A whole table at hand (a map of a file's bytes) is packed on several threads at once
(`pack_table`)."""

from __future__ import annotations

import math
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import numpy as np

from eas_vo import concurrency
from eas_vo.errors import DataError
from eas_vo.eventfile.kernels import check_and_pack_rows
from eas_vo.eventfile.validate import Validator
from eas_vo.types import EVENT_DTYPE


def pack_rows(
    rows: np.ndarray,
    columns: tuple[int, int, int, int],
    validate: Validator,
    first_row: int,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """EVENT_DTYPE records of the valid rows of `rows` ((N, k) float64, C order), in order.

    columns: the column indices of t [s], x, y [px] and p.
    first_row: the table index of rows[0], for errors (strict) and counted drops (lenient).
    out: EVENT_DTYPE records (at least N) to pack into, reused from block to block: the
        result is then a view of it when every row is valid. Default: a new array.
    """
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    events = np.empty(len(rows), EVENT_DTYPE) if out is None else out[: len(rows)]
    bad, last_t = check_and_pack_rows(
        rows, *columns, validate.last_t, validate.width, validate.height, validate.tolerance_s, events
    )
    if bad < 0:  # the common case: every row is valid
        validate.last_t = last_t
        return events
    return _checked_rows(rows, columns, validate, first_row)


def pack_table(
    rows: np.ndarray,
    columns: tuple[int, int, int, int],
    validate: Validator,
    write: Callable[[np.ndarray], object],
    block_rows: int = 1 << 18,
    threads: int = 0,
    group_rows: int = 0,
    touch: Callable[[int, int], object] | None = None,
) -> int:
    """Check and pack a whole table of rows ((N, k) float64 of either byte order, C order: a
    map of a file's bytes, say) and hand its valid records to `write`, in order; returns their
    count. Records, errors and drops (counted, and in the order the warnings list them) are
    those of pack_rows over groups of `group_rows` rows in turn (default: block_rows).

    Blocks of `block_rows` are checked and packed on `threads` threads at once (default:
    eas_vo.concurrency's count), each from the
    time of the row before it (the compiled pass releases the GIL); `write` runs on the
    calling thread. At its turn, a block is taken as it is if it had no problem and the blocks
    before it left the last time at the time of its previous row. Otherwise (a problem; a step
    back clamped or a row dropped just before it) it is packed again by pack_rows from the
    right time, together with the rest of its group in one pass: the first error raised is the
    earliest row's. Memory: threads + 1 blocks of records (and of native rows for another
    byte order). touch(start, stop), if given, runs on a packing thread before rows
    start..stop-1 are read (for a map: fault their pages in at once).
    """
    n = len(rows)
    threads = threads or concurrency.threads()
    size = max(1, min(block_rows, n))
    group = group_rows or size
    native = rows.dtype == np.dtype(np.float64)
    free = [
        (np.empty(size, EVENT_DTYPE), None if native else np.empty((size, rows.shape[1]), np.float64))
        for _ in range(threads + 1)
    ]

    def pack(start: int, buffers) -> tuple:
        events, scratch = buffers
        stop = min(start + size, n)
        if touch is not None:
            touch(start, stop)
        block = rows[start:stop]
        if scratch is not None:
            block = scratch[: stop - start]
            np.copyto(block, rows[start:stop])
        previous_t = float(rows[start - 1, columns[0]]) if start else -np.inf
        bad, last_t = check_and_pack_rows(
            block, *columns, previous_t, validate.width, validate.height, validate.tolerance_s, events[: stop - start]
        )
        return events[: stop - start], previous_t, bad, last_t

    total, pending, start = 0, deque(), 0
    pool = ThreadPoolExecutor(threads)
    try:
        while start < n or pending:
            while start < n and free:
                buffers = free.pop()
                pending.append((start, buffers, pool.submit(pack, start, buffers)))
                start += size
            first, buffers, future = pending.popleft()
            events, previous_t, bad, last_t = future.result()
            free.append(buffers)
            if bad < 0 and _same_time(previous_t, validate.last_t):  # what a pass in turn would have done
                validate.last_t = last_t
            else:
                stop = min(n, (first // group + 1) * group)
                while pending:  # the blocks under way start again after the group
                    _, buffers, future = pending.popleft()
                    future.result()
                    free.append(buffers)
                start = stop
                events = pack_rows(rows[first:stop], columns, validate, first)
            write(events)
            total += len(events)
    finally:
        pool.shutdown(cancel_futures=True)
    return total


def _same_time(a: float, b: float) -> bool:
    """a and b are one float64 (0.0 and -0.0 differ: a time clamped to either is written as it is)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


def _checked_rows(rows, columns, validate: Validator, first_row: int) -> np.ndarray:
    """The rows of a block with a problem, one verdict each: the earliest problem raises
    (strict); every bad row is dropped and counted once (lenient)."""
    col_t, *cols_xyp = columns
    t, xyp = rows[:, col_t], rows[:, cols_xyp]
    ints = np.where(np.abs(xyp) < 2.0**31, xyp, 0.5).astype(np.int64)  # NaN, inf, 1e300: never whole
    whole = (ints == xyp).all(axis=1)
    odd = np.flatnonzero(~whole)
    if len(odd) and not validate.lenient:
        j = int(odd[0])
        validate(t[:j], *ints[:j].T, lambda i: first_row + i)  # an earlier problem is named first
        x, y, p = xyp[j]
        raise DataError(
            validate.where, f"pixel coordinates and polarity must be integers: x y p = {x:g} {y:g} {p:g}", first_row + j
        )
    if len(odd):
        validate.warnings.add(
            validate.where, "pixel or polarity not an integer", f"{validate.unit} {first_row + int(odd[0])}", len(odd)
        )
    keep = np.flatnonzero(whole)
    return validate(t[keep], *ints[keep].T, lambda i: first_row + int(keep[i]))
