"""The line-by-line path for the pieces of a block that the compiled parser rejected: the
exact error (file and line) when strict, counted drops when lenient."""

from __future__ import annotations

import numpy as np

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile.kernels import POW10, parse_and_pack
from eas_vo.eventfile.validate import Validator
from eas_vo.types import EVENT_DTYPE


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


def sequential_piece(piece, first_line: int, validate: Validator, where: str, lenient: bool, warnings) -> tuple:
    """A piece the parallel pass could not take whole, in order: the compiled pass over each run
    of good lines, the line-by-line path (exact error, or counted drop) for each bad line.
    Returns (records, newlines)."""
    chunks, i, line = [], 0, first_line
    out = np.empty(len(piece) // 8 + 1, EVENT_DTYPE)
    while i < len(piece):
        rest = piece[i:]
        n, bad, lines, _, last_t = parse_and_pack(rest, POW10, validate.width, validate.height,
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
