"""The text path for the lines of a block that the compiled parser did not take: the exact
error (file and line) when strict, counted drops when lenient. Linear in the text: each line
is scanned a bounded number of times, whatever the mix of lines the compiled parser takes."""

from __future__ import annotations

import numpy as np

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile.kernels import parse_and_pack
from eas_vo.eventfile.validate import Validator
from eas_vo.io.tables import text_bytes
from eas_vo.types import EVENT_DTYPE

#: Lines the text path takes at once at most (so a file of lines the compiled parser does not
#: take costs one call a span, not a call a line).
MAX_SPAN_LINES = 4096


def _parse_line(parts: list[bytes]) -> tuple[list[float] | None, str, str]:
    """(row, "", "") for the fields of a `t x y p` line in numbers, else (None, kind, message)
    of its problem; whether the row is valid for the sensor is the Validator's to say."""
    if len(parts) != 4:
        return None, "malformed line", f"expected 4 columns (t x y p), found {len(parts)}"
    try:
        row = [float(v) for v in parts]
    except ValueError:
        return None, "malformed line", f"not a number in {b' '.join(parts)[:60].decode(errors='replace')!r}"
    if any(not (v - v == 0.0 and v == int(v)) for v in row[1:]):
        return (
            None,
            "pixel or polarity not an integer",
            f"pixel coordinates and polarity must be integers, found x y p = {' '.join(f'{v:g}' for v in row[1:])}",
        )
    return row, "", ""


def _slow_rows(text: bytes, first_line: int, where: str, lenient: bool, warnings: DataWarnings):
    """Line-by-line parse of `text` (whole lines, the first numbered `first_line`; blank and `#`
    comment lines skipped, whatever their place). Lenient:
    skips and counts bad lines. Strict: stops at the first and returns its error with the rows
    before it, so that an earlier invalid event can still be reported first."""
    rows, lines, pending = [], [], None
    for k, raw in enumerate(text.split(b"\n")):
        parts = (text_bytes(raw) if first_line + k == 1 else raw).split()
        if not parts or parts[0].startswith(
            b"#"
        ):  # a blank line, or a comment (`# t x y p`), as every table reads them
            continue
        row, kind, problem = _parse_line(parts)
        if row is None:
            if not lenient:
                pending = DataError(where, problem, first_line + k)
                break
            warnings.add(where, kind, f"line {first_line + k}")
            continue
        rows.append(row)
        lines.append(first_line + k)
    table = np.array(rows, dtype=float).reshape(-1, 4)
    columns = table[:, 0], *(table[:, k].astype(np.int64) for k in (1, 2, 3))
    return columns, lines, pending


def sequential_piece(piece, first_line: int, validate: Validator, where: str, lenient: bool, warnings) -> tuple:
    """A piece (ending with a newline) the parallel pass could not take whole, in order: the
    compiled pass over each run of lines it takes, the text path (exact error, or counted drop)
    for the others. Returns (records, newlines)."""
    chunks, i, line = [], 0, first_line
    out = np.empty(len(piece) // 8 + 1, EVENT_DTYPE)
    text = None  # the piece as bytes, copied once if a line needs the text path
    span = 1
    while i < len(piece):
        n, bad, lines, _, last_t = parse_and_pack(
            piece[i:], validate.width, validate.height, validate.tolerance_s, validate.last_t, out.view(np.uint8)
        )
        chunks.append(out[:n].copy())
        validate.last_t = last_t
        line += lines
        if bad < 0:
            break
        # Lines the compiled parser rejects come close together: the text path takes spans that
        # double while the compiled parser takes no more lines between them than the span held.
        span = min(2 * span, MAX_SPAN_LINES) if i > 0 and n <= span else 1
        text = piece.tobytes() if text is None else text
        start = end = i + bad
        taken = 0
        while taken < span and end < len(text):
            end = text.index(b"\n", end) + 1
            taken += 1
        columns, lines_of_rows, pending = _slow_rows(text[start:end], line, where, lenient, warnings)
        chunks.append(validate(*columns, lines_of_rows.__getitem__))
        if pending is not None:
            raise pending
        line += taken
        i = end
    return np.concatenate(chunks), line - first_line
