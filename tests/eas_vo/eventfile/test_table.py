"""Events as rows of numbers: the compiled pass and the row-by-row verdicts agree, blocks carry
the last time, and a pixel or polarity that is not a whole number is named by its row."""

import numpy as np
import pytest
from helpers import hostile_settings
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, pack_rows
from eas_vo.types import EVENT_DTYPE

WIDTH, HEIGHT = 640, 480


def table(n: int, seed: int = 0) -> np.ndarray:
    """n rows `t x y p` (p in {-1, 1}) on a 640x480 sensor, times increasing [s]."""
    rng = np.random.default_rng(seed)
    return np.column_stack([np.cumsum(rng.uniform(0, 1e-4, n)), rng.integers(0, WIDTH, n), rng.integers(0, HEIGHT, n),
                            rng.choice([-1.0, 1.0], n)])


def validator(lenient: bool = False, warnings: DataWarnings | None = None) -> Validator:
    return Validator("f.h5:events", WIDTH, HEIGHT, 1e-6, lenient, warnings if warnings is not None else DataWarnings(), "row")


def test_clean_rows_are_packed_exactly_in_any_column_order():
    rows = table(1000)
    expected = np.empty(1000, EVENT_DTYPE)
    expected["t"], expected["x"], expected["y"], expected["p"] = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3] > 0
    assert pack_rows(rows, (0, 1, 2, 3), validator(), 0).tobytes() == expected.tobytes()
    xytp = np.ascontiguousarray(rows[:, [1, 2, 0, 3]])  # MVSEC's order
    assert pack_rows(xytp, (2, 0, 1, 3), validator(), 0).tobytes() == expected.tobytes()


def test_blocks_carry_the_last_time():
    rows = table(100)
    rows[60, 0] = rows[59, 0] - 1.0  # goes back: named by its row in the whole table
    validate = validator()
    pack_rows(rows[:50], (0, 1, 2, 3), validate, 0)
    with pytest.raises(DataError, match=r"^f.h5:events:60: timestamp goes backwards"):
        pack_rows(rows[50:], (0, 1, 2, 3), validate, 50)
    validate = validator()
    pack_rows(rows[:60], (0, 1, 2, 3), validate, 0)
    rows[60, 0] = rows[59, 0] - 5e-7  # within the tolerance: clamped to the previous block's last time
    assert pack_rows(rows[60:], (0, 1, 2, 3), validate, 60)["t"][0] == rows[59, 0]


@pytest.mark.parametrize("column, value", [(1, 0.5), (2, 17.25), (3, 0.5), (3, -0.5), (1, np.nan), (2, -np.inf)])
def test_a_pixel_or_polarity_not_whole_is_named_or_dropped(column, value):
    rows = table(10)
    rows[[4, 7], column] = value
    with pytest.raises(DataError, match=r"^f.h5:events:4: pixel coordinates and polarity must be integers: x y p = "):
        pack_rows(rows, (0, 1, 2, 3), validator(), 0)
    warnings = DataWarnings()
    kept = pack_rows(rows, (0, 1, 2, 3), validator(True, warnings), 0)
    np.testing.assert_array_equal(kept["t"], rows[[0, 1, 2, 3, 5, 6, 8, 9], 0])
    assert warnings.lines() == ["f.h5:events: 2 dropped: pixel or polarity not an integer (first at row 4)"]


@hostile_settings(80)
@given(damage=st.lists(st.tuples(st.integers(0, 199), st.integers(0, 3),
                                 st.sampled_from([-1.0, 0.0, 0.5, 2.0, 479.0, 480.0, 640.0, 1e20, np.nan, np.inf, -5.0])),
                       max_size=6),
       lenient=st.booleans())
def test_the_compiled_pass_agrees_with_row_by_row_verdicts(damage, lenient):
    rows = table(200, seed=len(damage))
    for row, column, value in damage:
        rows[row, column] = rows[row, column] + value if column == 0 else value
    whole = np.all(np.isfinite(rows[:, 1:]) & (rows[:, 1:] == np.round(rows[:, 1:])) & (np.abs(rows[:, 1:]) < 2**31), axis=1)
    got_w, want_w = DataWarnings(), DataWarnings()
    try:
        got = pack_rows(rows, (0, 1, 2, 3), validator(lenient, got_w), 0)
    except DataError as exc:
        got = str(exc)
    # the reference: whole-number rows through the Validator alone, the others named first when earlier
    keep = np.flatnonzero(whole)
    odd = np.flatnonzero(~whole)
    reference = validator(lenient, want_w)
    try:
        if len(odd) and not lenient:
            reference(rows[: odd[0], 0], *rows[: odd[0], 1:].astype(np.int64).T, lambda i: i)
            want = f"f.h5:events:{odd[0]}: pixel coordinates and polarity must be integers"
        else:
            want = reference(rows[keep, 0], *rows[keep, 1:].astype(np.int64).T, lambda i: int(keep[i]))
            if len(odd):
                want_w.add("f.h5:events", "pixel or polarity not an integer", f"row {odd[0]}", len(odd))
    except DataError as exc:
        want = str(exc)
    if isinstance(want, str):
        assert isinstance(got, str) and got.startswith(want), (got, want)
    else:
        assert not isinstance(got, str), got
        assert got.tobytes() == want.tobytes()
        assert sorted(got_w.lines()) == sorted(want_w.lines())
