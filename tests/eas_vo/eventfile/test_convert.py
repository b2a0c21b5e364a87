"""The streaming text -> cache converter: blocks and line numbers across block boundaries, and
hostile text (hypothesis): one-line errors naming the line, or exactly the valid rows."""

import io

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import convert_text_to_cache, format_events
from eas_vo.types import EVENT_DTYPE
from helpers import hostile_number, hostile_settings, random_events


def test_blocks_and_line_numbers_span_block_boundaries():
    ev = random_events(20_000, seed=2)
    text = bytearray(format_events(ev))
    lines = text.split(b"\n")
    lines[15_000] = b"0.0 1 garbage 1"
    out = io.BytesIO()
    with pytest.raises(DataError, match=r"events.txt:15001: not a number"):
        convert_text_to_cache(io.BytesIO(b"\n".join(lines)), "events.txt", out, 240, 180, block_bytes=50_000)
    out = io.BytesIO()
    assert convert_text_to_cache(io.BytesIO(bytes(text)), "events.txt", out, 240, 180, block_bytes=50_000) == 20_000
    np.testing.assert_array_equal(np.frombuffer(out.getvalue(), EVENT_DTYPE), load_ref(text))


def load_ref(text):
    rows = np.array([line.split() for line in bytes(text).decode().splitlines()], dtype=float)
    ev = np.empty(len(rows), EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = rows.T
    return ev


line = st.one_of(
    st.tuples(
        st.floats(0, 10).map(lambda v: f"{v:.6f}"), st.integers(0, 239), st.integers(0, 179), st.integers(0, 1)
    ).map(lambda r: " ".join(map(str, r))),
    st.lists(hostile_number(), min_size=0, max_size=6).map(" ".join),
    st.binary(max_size=20).map(lambda b: b.decode("latin-1")),
)
text = st.lists(line, max_size=40).map("\n".join).map(lambda s: s.encode("utf-8", "replace"))


def reference_rows(data: bytes):
    """(t, x, y, p) of every line a reader must accept, by plain Python; None marks a line it must
    not; blank lines and `#` comments are neither."""
    rows = []
    for raw in data.split(b"\n"):
        parts = raw.split()
        if not parts or parts[0].startswith(b"#"):
            continue
        try:
            t, x, y, p = (float(v) for v in parts) if len(parts) == 4 else (None,) * 4
        except ValueError:
            t = None
        ok = (
            t is not None
            and np.isfinite(t)
            and 0 <= x < 240
            and 0 <= y < 180
            and x == int(x)
            and y == int(y)
            and p in (0, 1, -1)
        )
        rows.append((t, int(x), int(y), int(p > 0)) if ok else None)
    return rows


def convert(data: bytes, lenient: bool):
    out, warnings = io.BytesIO(), DataWarnings()
    n = convert_text_to_cache(io.BytesIO(data), "events.txt", out, 240, 180, 1e-6, lenient, warnings, block_bytes=64)
    events = np.frombuffer(out.getvalue(), EVENT_DTYPE)
    assert len(events) == n
    return events, warnings


def assert_events_are(events, rows) -> None:
    """The events hold exactly `rows`, times within the clamping tolerance."""
    assert len(events) == len(rows)
    if rows:
        t, x, y, p = (np.array(c) for c in zip(*rows))
        np.testing.assert_allclose(events["t"], t, atol=1.1e-6, rtol=0)
        assert (events["x"] == x).all() and (events["y"] == y).all() and (events["p"] == p).all()


@hostile_settings()
@given(text)
def test_hostile_text_strict_is_a_one_line_error_or_every_line(data):
    rows = reference_rows(data)
    try:
        events, _ = convert(data, lenient=False)
    except DataError as exc:
        assert "\n" not in str(exc) and exc.line is not None and 1 <= exc.line <= data.count(b"\n") + 1
        return
    assert None not in rows  # accepted: every line was valid, and it is all there
    assert_events_are(events, rows)


@hostile_settings()
@given(text)
def test_hostile_text_lenient_keeps_the_valid_rows_and_counts_every_drop(data):
    rows = reference_rows(data)
    events, warnings = convert(data, lenient=True)
    assert len(events) + sum(warnings.counts.values()) == len(rows)
    kept = [r for r in rows if r is not None]
    if len(events) == len(kept):  # no valid row dropped for going back in time: the same rows
        assert_events_are(events, kept)


def _convert_cpu_s(data: bytes, lenient: bool) -> float:
    """CPU seconds of this process (not wall time: other work on the machine does not count)
    converting `data` in one block, the best of three."""
    import time

    best = np.inf
    for _ in range(3):
        start = time.process_time()
        convert_text_to_cache(io.BytesIO(data), "events.txt", io.BytesIO(), 240, 180, 1e-6, lenient, DataWarnings())
        best = min(best, time.process_time() - start)
    return best


@pytest.mark.parametrize(
    "lenient, line",
    [
        (False, "{t:e} {x} 33 1{pad}\n"),  # valid, in a form only the text path reads (an exponent)
        (True, "{t:.6f} {x}.5 33 1{pad}\n"),  # dropped and counted: a pixel coordinate that is not an integer
        (False, "{t:e} {x} 33 1{pad}\n{t:.6f} {x} 34 0{pad}\n"),  # the two paths taking turns
    ],
)
def test_the_text_path_is_linear_in_the_lines(lenient, line):
    """Lines the compiled parser does not take cost the same per line however many there are:
    4x the lines take under 8x the time. Each line ends in 1000 blanks (allowed), so that a path
    scanning the rest of the text for each such line, as it once did, shows its 16x at a size a
    test can afford."""

    def text(n):
        return "".join(line.format(t=k * 1e-6, x=k % 240, pad=" " * 1000) for k in range(n)).encode()

    few, many = _convert_cpu_s(text(4000), lenient), _convert_cpu_s(text(16_000), lenient)
    assert many < 8 * few, (few, many)


def test_pixel_coordinates_that_are_not_integers_are_named_or_counted():
    data = b"0.1 1 2 1\n0.5 120.5 33.0 1\n0.6 120 33 1\n"
    with pytest.raises(
        DataError,
        match=r"^events.txt:2: pixel coordinates and polarity must be integers, "
        r"found x y p = 120.5 33 1$",
    ):
        convert(data, lenient=False)
    events, warnings = convert(data, lenient=True)
    assert events["x"].tolist() == [1, 120]
    assert warnings.lines() == ["events.txt: 1 dropped: pixel or polarity not an integer (first at line 2)"]
