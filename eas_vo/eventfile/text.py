"""Writing events as ECD text (`t x y p` per line, t in seconds with 9 decimals: 1 ns), and
priming the binary cache of the file written."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eas_vo.eventfile.cache import prime_text_cache
from eas_vo.io.atomic import atomic_file
from eas_vo.types import EVENT_DTYPE


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


def format_events(events: np.ndarray, origin_ns: int = 0) -> bytes:
    """EVENT_DTYPE -> ECD text lines `t x y p` (t [s] after the clock origin `origin_ns`, written
    as the recording's own time with 9 decimals, summed in integer ns), vectorised."""
    n = len(events)
    if n == 0:
        return b""
    t_ns = np.round(events["t"] * 1e9).astype(np.int64) + origin_ns
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


def write_events_text(
    path: str | Path, events: np.ndarray, width: int, height: int, chunk: int = 1_000_000, origin_ns: int = 0
) -> None:
    """Write events (t [s] after the clock origin `origin_ns`) as ECD `events.txt` atomically,
    and prime the binary cache with the times as the text will parse back (rounded to 1 ns;
    not primed after an origin, where the parse rounds at the absolute time's magnitude)."""
    path = Path(path)
    events = np.array(events, dtype=EVENT_DTYPE)
    events["t"] = np.round(events["t"] * 1e9) / 1e9
    if (np.diff(events["t"]) < 0).any():
        raise ValueError("write_events_text needs events sorted by time")
    with atomic_file(path) as fh:
        for start in range(0, len(events), chunk):
            fh.write(format_events(events[start : start + chunk], origin_ns))
    if origin_ns == 0:
        prime_text_cache(path, events, width, height)
