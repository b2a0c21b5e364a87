"""Numba-compiled kernels: parse `t x y p` lines, validate rows against the sensor and the
previous time (seconds), and pack them into EVENT_DTYPE records (13 bytes each, little-endian).

Compiled with `cache=True`: the machine code is kept on disk beside this file.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: 10**k, k = 0..22: each exact in float64 (5**22 < 2**53).
POW10 = np.array([float(10**k) for k in range(23)])
_TWO53_INT = 1 << 53
#: Integer seconds s with s * 10**k + (k fraction digits) < 2**53, for k = 0..15: below
#: _SECONDS_EXACT[k], a time's whole decimal mantissa is an exact float64.
_SECONDS_EXACT = np.array([_TWO53_INT // 10**k for k in range(16)], np.int64)
_IPOW10 = np.array([10**k for k in range(16)], np.int64)
#: The integer part of a time the compiled parser takes: below this, s * 10 + 9 < 2**53.
_SECONDS_MAX = (_TWO53_INT - 10) // 10
#: Fraction digits are kept while the kept ones are below this (at most 18 digits: an int64).
_FRACTION_KEPT = 10**17
#: Rows a table kernel checks at once: the block's rows stay in the L1 cache between its two passes.
TABLE_CHUNK_ROWS = 1024


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


@numba.njit(cache=True, nogil=True, inline="always")
def _decimal_time(sec, frac, dec, truncated):
    """The float64 nearest to the time `sec` + `frac` / 10**dec [s] (`truncated`: nonzero digits
    beyond the dec-th were dropped), or NaN where this cannot be sure of the nearest (a text
    path decides those lines). sec < 2**53, dec <= 22.

    Whole mantissa below 2**53: one exact division (correctly rounded). Else (Unix times with
    nanoseconds): S = sec exact, F = frac / 10**dec correctly rounded (error at most F 2**-53,
    taken as F 2**-51; plus 10**-dec when truncated), s = S + F and its exact error e
    (Fast2Sum: |S| >= |F|); s is the nearest double to the decimal unless the exact value may
    lie at or beyond the midpoint between s and a neighbour, which is when |e| plus that bound
    reaches half a unit in the last place of s."""
    if not truncated and frac < _TWO53_INT:
        if sec == 0:
            return frac / POW10[dec]
        if dec < 16 and sec < _SECONDS_EXACT[dec]:
            return (sec * _IPOW10[dec] + frac) / POW10[dec]
    big = float(sec)
    small = frac / POW10[dec]
    s = big + small
    err = small - (s - big)
    bound = small * 4.440892098500626e-16 + (2.0 / POW10[dec] if truncated else 0.0)
    m, e = math.frexp(s)
    half_up = math.ldexp(1.0, e - 54)
    half_down = half_up * 0.5 if m == 0.5 else half_up
    if err + bound < half_up and bound - err < half_down:
        return s
    return np.nan


@numba.njit(cache=True, nogil=True, error_model="numpy")
def parse_and_pack(buf, width, height, tolerance_s, last_t, out):
    """Parse, validate and pack `t x y p` lines of `buf` (which ends with a newline: it stops
    every scan) into EVENT_DTYPE records in the bytes `out`, after a previous time `last_t`.

    A time has any number of digits before and after its point (the integer part below
    2**53 / 10 s); it is the float64 nearest to its decimal text (_decimal_time), whatever
    its clock's origin (Unix times with nanoseconds too). A pixel coordinate or polarity is a
    whole number, written with or without a fraction of zeros (`120`, `120.`, `120.000`).

    Returns (rows, byte offset of the first line that is not in that form or not valid, or
    -1, newlines before it, first time, last time).

    The digit loops are written out on purpose, as an inlined helper runs slower
    (docs/speed.md, "The event parser and its cache"). The scan index is unsigned to spare
    numba's negative-index checks.
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
        sec = 0
        nd = 0
        while 48 <= c <= 57:
            if sec > _SECONDS_MAX:
                return n, np.int64(start), lines, first_t, last_t
            sec = sec * 10 + (c - 48)
            nd += 1
            i += one
            c = buf[i]
        frac = 0
        dec = 0
        truncated = False
        if c == 46:
            i += one
            c = buf[i]
            while 48 <= c <= 57:
                if frac < _FRACTION_KEPT:
                    frac = frac * 10 + (c - 48)
                    dec += 1
                elif c != 48:
                    truncated = True
                i += one
                c = buf[i]
        if nd + dec == 0 or dec > 22 or not (c == 32 or c == 9):
            return n, np.int64(start), lines, first_t, last_t
        t = _decimal_time(sec, frac, dec, truncated)
        if t != t:
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
            if c == 46:  # a whole number written with a fraction of zeros
                i += one
                c = buf[i]
                while c == 48:
                    i += one
                    c = buf[i]
            if m == 0 or m > 6 or 48 <= c <= 57:
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
        ok, t = _accept(t, x, y, p, last_t, width, height, tolerance_s)
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


@numba.njit(cache=True, nogil=True)
def check_and_pack(ticks, per_second, x, y, p, last_t, width, height, tolerance_s, events):
    """Validate parsed rows and pack them into the EVENT_DTYPE records `events`; row i's time
    [s] is ticks[i] / per_second (per_second 1: seconds already; integer microseconds or
    nanoseconds divided as numpy divides them). Returns (index of the first row with any
    problem or -1, the last timestamp); rows before a problem are packed.

    Block by block (TABLE_CHUNK_ROWS): pack every row, then check the block in one
    branch-free pass; a block that is not plain (a problem, or a small step back to clamp) is
    checked and packed again row by row."""
    n = len(ticks)
    for a in range(0, n, TABLE_CHUNK_ROWS):
        e = min(a + TABLE_CHUNK_ROWS, n)
        bad = False
        prev = last_t
        for i in range(a, e):
            t = ticks[i] / per_second
            r = events[i]
            r.t, r.x, r.y, r.p = (
                t,
                np.uint16(x[i]),
                np.uint16(y[i]),
                p[i] > 0,
            )  # any value: a block not plain is packed again
            bad |= not (
                (x[i] >= 0)
                & (x[i] < width)
                & (y[i] >= 0)
                & (y[i] < height)
                & (p[i] >= -1)
                & (p[i] <= 1)
                & (t >= prev)
                & (t - t == 0.0)
            )
            prev = t
        if not bad:
            last_t = prev
            continue
        for i in range(a, e):
            ok, t = _accept(ticks[i] / per_second, x[i], y[i], p[i], last_t, width, height, tolerance_s)
            if not ok:
                return i, last_t
            last_t = t
            r = events[i]
            r.t, r.x, r.y, r.p = t, x[i], y[i], p[i] > 0
    return -1, last_t


#: 2**52: (v + 2**52) - 2**52 == v for 0 <= v < 2**52 exactly when v is a whole number.
_TWO52 = 4503599627370496.0


@numba.njit(cache=True, nogil=True)
def _plain_rows(rows, a, e, col_t, col_x, col_y, col_p, last_t, width, height):
    """Whether rows a..e-1 are all plain: pixel whole numbers on the sensor, polarity -1, 0 or
    1, time finite and not before the previous row's (last_t for row a). No branch in the
    loop, so that it runs on vectors; a block that is not plain is taken row by row."""
    bad = False
    for i in range(a, e):
        xf, yf, pf, t = rows[i, col_x], rows[i, col_y], rows[i, col_p], rows[i, col_t]
        prev = rows[i - 1, col_t] if i > a else last_t
        bad |= not (
            (xf >= 0.0)
            & (xf < width)
            & (yf >= 0.0)
            & (yf < height)
            & ((xf + _TWO52) - _TWO52 == xf)
            & ((yf + _TWO52) - _TWO52 == yf)
            & ((pf == 1.0) | (pf == -1.0) | (pf == 0.0))
            & (t >= prev)
            & (t - t == 0.0)
        )
    return not bad


@numba.njit(cache=True, nogil=True)
def check_and_pack_rows(rows, col_t, col_x, col_y, col_p, last_t, width, height, tolerance_s, events):
    """check_and_pack for events held as float64 rows of a table (columns col_t, col_x, col_y,
    col_p of `rows`) into the EVENT_DTYPE records `events`: a pixel coordinate or polarity that
    is not a whole number is a problem too. Returns (index of the first row with any problem
    or -1, the last timestamp); rows before a problem are packed.

    Block by block (TABLE_CHUNK_ROWS): pack every row, then check the block in one branch-free
    pass; a block that is not plain (a problem, or a small step back to clamp) is checked and
    packed again row by row."""
    n = rows.shape[0]
    for a in range(0, n, TABLE_CHUNK_ROWS):
        e = min(a + TABLE_CHUNK_ROWS, n)
        for i in range(a, e):
            r = events[i]
            r.t = rows[i, col_t]
            r.x = np.uint16(np.int32(rows[i, col_x]))  # any value: a block not plain is packed again
            r.y = np.uint16(np.int32(rows[i, col_y]))
            r.p = rows[i, col_p] > 0.0
        if _plain_rows(rows, a, e, col_t, col_x, col_y, col_p, last_t, width, height):
            last_t = rows[e - 1, col_t]
            continue
        for i in range(a, e):
            xf, yf, pf = rows[i, col_x], rows[i, col_y], rows[i, col_p]
            if not (0.0 <= xf < 65536.0 and 0.0 <= yf < 65536.0 and -1.0 <= pf <= 1.0):  # also NaN
                return i, last_t
            x, y, p = np.int64(xf), np.int64(yf), np.int64(pf)
            if x != xf or y != yf or p != pf:
                return i, last_t
            ok, t = _accept(rows[i, col_t], x, y, p, last_t, width, height, tolerance_s)
            if not ok:
                return i, last_t
            last_t = t
            r = events[i]
            r.t, r.x, r.y, r.p = t, x, y, 1 if p > 0 else 0
    return -1, last_t


@numba.njit(cache=True, nogil=True)
def check_and_pack_dv(words, origin_us, last_t, width, height, tolerance_s, events):
    """check_and_pack for DV's 16-byte `Event` records (AEDAT4) seen as int64 word pairs
    (`words`, shape (n, 2), little-endian): word 0 the timestamp [us], word 1 x (int16, bits
    0-15), y (int16, bits 16-31), polarity (uint8, bits 32-39). Times [s] are (ticks - origin_us)
    / 1e6 as numpy computes them (the clock origin: Dataset.clock_origin_ns). Returns (index of the first row with any problem or -1, the last
    timestamp); rows before a problem are packed.

    The same verdicts and records as check_and_pack on the records' fields, faster (docs/speed.md,
    "Recordings in other formats"): each record is two loads, and a pixel is checked as one
    unsigned compare (a negative int16 is 65535 or less as unsigned; below min(size, 32768)
    means 0 <= value < size)."""
    n = words.shape[0]
    x_end, y_end = min(width, 32768), min(height, 32768)
    for a in range(0, n, TABLE_CHUNK_ROWS):
        e = min(a + TABLE_CHUNK_ROWS, n)
        bad = False
        prev = last_t
        for i in range(a, e):
            t = (words[i, 0] - origin_us) / 1e6
            w = words[i, 1]
            x, y, p = w & 0xFFFF, (w >> 16) & 0xFFFF, (w >> 32) & 0xFF
            r = events[i]
            r.t, r.x, r.y, r.p = t, np.uint16(x), np.uint16(y), p > 0  # any value: a block not plain is packed again
            bad |= not ((x < x_end) & (y < y_end) & (p <= 1) & (t >= prev))
            prev = t
        if not bad:
            last_t = prev
            continue
        for i in range(a, e):
            w = words[i, 1]
            x, y, p = np.int16(w & 0xFFFF), np.int16((w >> 16) & 0xFFFF), (w >> 32) & 0xFF
            ok, t = _accept((words[i, 0] - origin_us) / 1e6, x, y, p, last_t, width, height, tolerance_s)
            if not ok:
                return i, last_t
            last_t = t
            r = events[i]
            r.t, r.x, r.y, r.p = t, np.uint16(x), np.uint16(y), p > 0
    return -1, last_t
