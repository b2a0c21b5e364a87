"""Numeric text tables, the event text format and the binary event cache."""

import os

import numpy as np
import pytest

from eas_vo.errors import DataError
from eas_vo.io import event_cache_path, format_events, load_events, parse_events_text, read_table, write_events_text
from eas_vo.types import EVENT_DTYPE


def random_events(n, seed=0):
    rng = np.random.default_rng(seed)
    ev = np.empty(n, EVENT_DTYPE)
    ev["t"] = np.sort(rng.uniform(0, 1234.5, n))
    ev["x"] = rng.integers(0, 240, n)
    ev["y"] = rng.integers(0, 180, n)
    ev["p"] = rng.integers(0, 2, n)
    return ev


def test_format_events_matches_printf():
    ev = random_events(500)
    expected = "".join(f"{e['t']:.9f} {e['x']} {e['y']} {e['p']}\n" for e in ev)
    assert format_events(ev).decode() == expected


def test_text_round_trip_and_cache(tmp_path):
    ev = random_events(10_000, seed=1)
    path = tmp_path / "events.txt"
    write_events_text(path, ev)
    parsed = parse_events_text(path, 240, 180)
    np.testing.assert_array_equal(parsed[["x", "y", "p"]], ev[["x", "y", "p"]])
    np.testing.assert_allclose(parsed["t"], ev["t"], atol=1e-9)
    cached = load_events(path, 240, 180)
    assert isinstance(cached, np.memmap) or isinstance(cached.base, np.memmap)
    np.testing.assert_array_equal(cached, parsed)  # the primed cache equals a fresh parse, bit for bit


def test_cache_is_invalidated_when_the_file_changes(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n")
    first = load_events(path, 240, 180)
    assert event_cache_path(path).exists() and len(first) == 2
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n0.3 5 6 1\n")
    os.utime(path, ns=(1, 2))  # a different modification time as well as size
    assert len(load_events(path, 240, 180)) == 3


@pytest.mark.parametrize(
    "text,line,message",
    [
        ("0.1 1 2 1\n0.2 3 x 0\n", 2, "not a number"),
        ("0.1 1 2 1\n0.2 3 4\n", 2, "expected 4 columns"),
        ("0.1 1 2 1\n0.2 3 4 0\n0.15 1 1 1\n", 3, "goes back"),
        ("0.1 1 2 1\n0.2 300 4 0\n", 2, "outside the 240x180 sensor"),
        ("0.1 1 2 1\n0.2 3 4 7\n", 2, "polarity"),
        ("0.1 1 2 1\n0.2 nan 4 0\n", 2, "NaN"),
    ],
)
def test_malformed_events_name_file_and_line(tmp_path, text, line, message):
    path = tmp_path / "events.txt"
    path.write_text(text)
    with pytest.raises(DataError, match=message) as info:
        parse_events_text(path, 240, 180)
    assert info.value.line == line and str(info.value).startswith(f"{path}:{line}:")


def test_read_table_skips_comments_and_blank_lines(tmp_path):
    path = tmp_path / "t.txt"
    path.write_text("# header\n1 2 3\n\n4 5 6\n")
    np.testing.assert_array_equal(read_table(path, 3, "a b c"), [[1, 2, 3], [4, 5, 6]])
