"""Events as rows of numbers: the compiled pass and the row-by-row verdicts agree, blocks carry
the last time, and a pixel or polarity that is not a whole number is named by its row."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, pack_rows, pack_table
from eas_vo.types import EVENT_DTYPE
from helpers import hostile_settings

WIDTH, HEIGHT = 640, 480


def table(n: int, seed: int = 0) -> np.ndarray:
    """n rows `t x y p` (p in {-1, 1}) on a 640x480 sensor, times increasing [s]."""
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [
            np.cumsum(rng.uniform(0, 1e-4, n)),
            rng.integers(0, WIDTH, n),
            rng.integers(0, HEIGHT, n),
            rng.choice([-1.0, 1.0], n),
        ]
    )


def validator(lenient: bool = False, warnings: DataWarnings | None = None) -> Validator:
    return Validator(
        "f.h5:events", WIDTH, HEIGHT, 1e-6, lenient, warnings if warnings is not None else DataWarnings(), "row"
    )


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
@given(
    damage=st.lists(
        st.tuples(
            st.integers(0, 199),
            st.integers(0, 3),
            st.sampled_from([-1.0, 0.0, 0.5, 2.0, 479.0, 480.0, 640.0, 1e20, np.nan, np.inf, -5.0]),
        ),
        max_size=6,
    ),
    lenient=st.booleans(),
)
def test_the_compiled_pass_agrees_with_row_by_row_verdicts(damage, lenient):
    rows = table(200, seed=len(damage))
    for row, column, value in damage:
        rows[row, column] = rows[row, column] + value if column == 0 else value
    whole = np.all(
        np.isfinite(rows[:, 1:]) & (rows[:, 1:] == np.round(rows[:, 1:])) & (np.abs(rows[:, 1:]) < 2**31), axis=1
    )
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


def in_turn(rows: np.ndarray, group: int, lenient: bool):
    """pack_rows over groups of `group` rows in turn: (records, warning lines), or the error."""
    warnings = DataWarnings()
    validate = validator(lenient, warnings)
    try:
        parts = [pack_rows(rows[a : a + group], (0, 1, 2, 3), validate, a).copy() for a in range(0, len(rows), group)]
    except DataError as exc:
        return str(exc)
    return np.concatenate(parts) if parts else np.empty(0, EVENT_DTYPE), warnings.lines()


def packed_table(rows: np.ndarray, block: int, group: int, lenient: bool, threads: int = 2):
    """pack_table's records and warning lines (or its error), and the rows `touch` was given."""
    warnings, parts, touched = DataWarnings(), [], []
    try:
        count = pack_table(
            rows,
            (0, 1, 2, 3),
            validator(lenient, warnings),
            lambda ev: parts.append(ev.copy()),
            block,
            threads,
            group,
            touch=lambda a, b: touched.append((a, b)),
        )
    except DataError as exc:
        return str(exc), touched
    events = np.concatenate(parts) if parts else np.empty(0, EVENT_DTYPE)
    assert count == len(events)
    return (events, warnings.lines()), touched


@hostile_settings(120)
@given(
    damage=st.lists(
        st.tuples(
            st.integers(1, 2999),
            st.integers(0, 3),
            st.sampled_from([-0.5, -5e-7, -1e-9, 0.5, 640.0, -1.0, np.nan, np.inf, 1e300]),
        ),
        max_size=6,
    ),
    near_seams=st.booleans(),
    block=st.sampled_from([1, 7, 100, 256, 1024, 5000]),
    group=st.sampled_from([0, 300, 1000]),
    lenient=st.booleans(),
    big_endian=st.booleans(),
    threads=st.sampled_from([1, 2, 3]),
)
def test_pack_table_is_pack_rows_over_groups_in_turn(damage, near_seams, block, group, lenient, big_endian, threads):
    """On several threads, blocks packed from the previous row's time, a block taken again
    when it had a problem or the time before it was clamped or dropped: the same records, the
    same first error, the same drops listed in the same order as one pass over the groups."""
    rows = table(3000, seed=len(damage))
    for row, column, value in damage:
        if near_seams:
            row = min(2999, max(1, row // block * block + row % 3 - 1))
        rows[row, column] = rows[row - 1, column] + value if column == 0 else value
    got, touched = packed_table(rows.astype(">f8") if big_endian else rows, block, group, lenient, threads)
    want = in_turn(rows, group or block, lenient)
    if isinstance(want, str):
        assert got == want
        return
    assert not isinstance(got, str), got
    assert got[0].tobytes() == want[0].tobytes()
    assert got[1] == want[1]
    assert all(b - a <= block for a, b in touched)


def test_pack_table_of_no_rows_writes_nothing():
    assert packed_table(np.empty((0, 4)), 100, 0, False)[0][0].size == 0


def test_pack_table_tells_minus_zero_from_zero():
    """A block packed from the time -0.0 of the row before it is not taken when the last time
    kept is 0.0 (that row was dropped): a step back clamped to it is written as 0.0."""
    rows = table(8)
    rows[:, 0] = [-3e-7, -2e-7, -1e-7, 0.0, -0.0, -1e-7, 1e-6, 2e-6]
    rows[4, 1] = WIDTH  # dropped: off the sensor
    (events, lines), _ = packed_table(rows, 5, 5, True)
    assert events["t"][4] == 0.0 and np.signbit(events["t"][3:5]).tolist() == [False, False]
    assert lines == ["f.h5:events: 1 dropped: pixel outside the 640x480 sensor (first at row 4)"]
