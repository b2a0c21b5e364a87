"""Event text files: the compiled parser, validation, lenient mode and the binary cache."""

import io
import os

import numpy as np
import pytest

from eas_vo.errors import DataError
from eas_vo.eventfile import (
    DataWarnings,
    cache_key,
    cache_path,
    convert_text_to_cache,
    file_identity,
    format_events,
    load_event_text,
    parse_block,
    write_events_text,
)
from eas_vo.types import EVENT_DTYPE


def random_events(n, seed=0):
    rng = np.random.default_rng(seed)
    ev = np.empty(n, EVENT_DTYPE)
    ev["t"] = np.sort(rng.uniform(0, 1234.5, n))
    ev["x"] = rng.integers(0, 240, n)
    ev["y"] = rng.integers(0, 180, n)
    ev["p"] = rng.integers(0, 2, n)
    return ev


def load_file(path, lenient=False, warnings=None, width=240, height=180, tolerance_s=1e-6):
    return load_event_text(lambda: open(path, "rb"), file_identity(path), str(path), width, height, tolerance_s, lenient, warnings)


def test_format_events_matches_printf():
    ev = random_events(500)
    expected = "".join(f"{e['t']:.9f} {e['x']} {e['y']} {e['p']}\n" for e in ev)
    assert format_events(ev).decode() == expected


def test_compiled_parser_equals_python_float_exactly():
    rng = np.random.default_rng(3)
    text = "".join(
        f"{t:.{d}f} {x} {y} {p}\n"
        for t, d, x, y, p in zip(rng.uniform(0, 5000, 3000), rng.integers(0, 10, 3000), rng.integers(0, 240, 3000),
                                 rng.integers(0, 180, 3000), rng.integers(0, 2, 3000))
    ) + "7 1 2 -1\r\n  \n0.5\t3  4 1"  # integer time, CRLF, -1 polarity, blank line, tabs, no final newline
    ev = parse_block(np.frombuffer(text.encode(), np.uint8), tolerance_s=np.inf)
    rows = [line.split() for line in text.splitlines() if line.strip()]
    t = np.maximum.accumulate([float(r[0]) for r in rows])  # steps back are clamped
    np.testing.assert_array_equal(ev["t"], t)  # bit-exact
    np.testing.assert_array_equal(ev["x"], [int(r[1]) for r in rows])
    np.testing.assert_array_equal(ev["y"], [int(r[2]) for r in rows])
    np.testing.assert_array_equal(ev["p"], [int(r[3]) > 0 for r in rows])


def test_parser_in_two_threads_equals_one():
    from eas_vo.eventfile import BlockParser

    ev = random_events(200_000, seed=4)
    buf = np.frombuffer(format_events(ev), np.uint8)
    parser = BlockParser(240, 180, 1e-6, threads=2)
    pieces = parser(buf)
    parser.close()
    assert len(pieces) == 2 and all(packed is not None for _, packed in pieces)
    np.testing.assert_array_equal(np.concatenate([packed[0] for _, packed in pieces]), parse_block(buf))
    np.testing.assert_allclose(parse_block(buf)["t"], ev["t"], atol=5e-10)


@pytest.mark.parametrize("text", ["1e-3 1 2 1\n", "-0.5 1 2 1\n", "0.1 1 2\n", "0.1 1 2 1 9\n", "0.1 1.5 2 1\n"])
def test_unusual_lines_leave_the_fast_path(text):
    assert parse_block(np.frombuffer(text.encode(), np.uint8)) is None


def test_round_trip_through_text_and_cache(tmp_path):
    ev = random_events(50_000, seed=1)
    path = tmp_path / "events.txt"
    write_events_text(path, ev, 240, 180)  # primes the cache
    primed = load_file(path)
    os.unlink(cache_path(cache_key("text", *file_identity(path), 240, 180, 1e-6)))
    parsed = load_file(path)  # parsed from text this time
    assert isinstance(parsed, np.memmap)
    np.testing.assert_array_equal(parsed, primed)  # the primed cache equals a fresh parse, bit for bit
    np.testing.assert_array_equal(parsed[["x", "y", "p"]], ev[["x", "y", "p"]])
    np.testing.assert_allclose(parsed["t"], ev["t"], atol=1e-9)


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


def test_cache_is_invalidated_when_the_file_changes(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n")
    assert len(load_file(path)) == 2
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n0.3 5 6 1\n")
    os.utime(path, ns=(1, 2))
    assert len(load_file(path)) == 3


BAD = [
    ("0.1 1 2 1\n0.2 3 x 0\n", 2, "not a number"),
    ("0.1 1 2 1\n0.2 3 4\n", 2, "expected 4 columns"),
    ("0.1 1 2 1\n0.2 3 4 0\n0.15 1 1 1\n", 3, "timestamp goes backwards"),
    ("0.1 1 2 1\n0.2 300 4 0\n", 2, "outside the 240x180 sensor"),
    ("0.1 1 2 1\n0.2 3 4 7\n", 2, "polarity"),
    ("0.1 1 2 1\n0.2 nan 4 0\n", 2, "not a number|integers"),
    ("0.1 1 2 1\n0.2 3 4 0\n0.3 5", 3, "expected 4 columns"),  # truncated last line
]


@pytest.mark.parametrize("text,line,message", BAD)
def test_malformed_events_name_file_and_line(tmp_path, text, line, message):
    path = tmp_path / "events.txt"
    path.write_text(text)
    with pytest.raises(DataError, match=message) as info:
        load_file(path)
    assert info.value.line == line and str(info.value).startswith(f"{path}:{line}:")


@pytest.mark.parametrize("text,line,message", BAD)
def test_lenient_drops_and_counts(tmp_path, text, line, message):
    path = tmp_path / "events.txt"
    path.write_text(text)
    warnings = DataWarnings()
    events = load_file(path, lenient=True, warnings=warnings)
    assert len(events) == text.count("\n") + (not text.endswith("\n")) - 1
    (report,) = warnings.lines()
    assert f"1 dropped" in report and f"(first at line {line})" in report
    again = DataWarnings()
    load_file(path, lenient=True, warnings=again)  # from the cache: the warning is reported again
    assert again.lines() == warnings.lines()
    with pytest.raises(DataError):
        load_file(path)  # the lenient cache never serves a strict read


def test_small_steps_back_within_tolerance_are_clamped(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2000000 3 4 0\n0.1999995 5 6 1\n0.3 1 1 1\n")
    t = load_file(path)["t"]
    np.testing.assert_array_equal(t, [0.1, 0.2, 0.2, 0.3])
    with pytest.raises(DataError, match="goes backwards"):
        load_file(path, tolerance_s=1e-7)


def test_search_times_equals_searchsorted_without_copying(tmp_path):
    from eas_vo.types import search_times

    ev = random_events(100_000, seed=9)
    ev["t"][1000:1010] = ev["t"][1000]  # ties
    queries = np.concatenate([[-1.0, ev["t"][1000], 1e9], np.random.default_rng(0).uniform(0, 1300, 500)])
    np.testing.assert_array_equal(search_times(ev, queries), np.searchsorted(ev["t"], queries, side="left"))
    assert len(search_times(ev[:0], [1.0])) == 1 and search_times(ev[:0], [1.0])[0] == 0


def test_strict_reports_the_earliest_bad_line_whatever_its_problem(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 3 4 5\n0.3 999 4 1\n")  # line 2: polarity, line 3: off the sensor
    with pytest.raises(DataError, match="polarity") as info:
        load_file(path)
    assert info.value.line == 2
    warnings = DataWarnings()
    assert len(load_file(path, lenient=True, warnings=warnings)) == 1
    assert sorted(warnings.lines()) == sorted([
        f"{path}: 1 dropped: polarity not 0/1 (or -1/1) (first at line 2)",
        f"{path}: 1 dropped: pixel outside the 240x180 sensor (first at line 3)",
    ])
