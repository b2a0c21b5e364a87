"""Events held as rows of numbers (MVSEC's HDF5 `x y t p` float64 array, for one), checked
and packed into EVENT_DTYPE records one block at a time: pixel and polarity whole numbers,
then the Validator's checks (pixel on the sensor, time finite and not going back), the last
time carried from block to block. Rows are named by their index in the table (from 0)."""

from __future__ import annotations

import numpy as np

from eas_vo.errors import DataError
from eas_vo.eventfile.kernels import check_and_pack_rows
from eas_vo.eventfile.validate import Validator
from eas_vo.types import EVENT_DTYPE


def pack_rows(rows: np.ndarray, columns: tuple[int, int, int, int], validate: Validator, first_row: int) -> np.ndarray:
    """EVENT_DTYPE records of the valid rows of `rows` ((N, k) float64, C order), in order.

    columns: the column indices of t [s], x, y [px] and p.
    first_row: the table index of rows[0], for errors (strict) and counted drops (lenient).
    """
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    events = np.empty(len(rows), EVENT_DTYPE)
    bad, last_t = check_and_pack_rows(rows, *columns, validate.last_t, validate.width, validate.height,
                                      validate.tolerance_s, events.view(np.uint8))
    if bad < 0:  # the common case: every row is valid
        validate.last_t = last_t
        return events
    return _checked_rows(rows, columns, validate, first_row)


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
        raise DataError(validate.where, f"pixel coordinates and polarity must be integers: x y p = {x:g} {y:g} {p:g}",
                        first_row + j)
    if len(odd):
        validate.warnings.add(validate.where, "pixel or polarity not an integer", f"{validate.unit} {first_row + int(odd[0])}",
                              len(odd))
    keep = np.flatnonzero(whole)
    return validate(t[keep], *ints[keep].T, lambda i: first_row + int(keep[i]))
