"""Writing event text: printf-exact formatting and the round trip through text and cache."""

import os

import numpy as np

from eas_vo.eventfile import cache_key, cache_path, file_identity, format_events, write_events_text
from helpers import load_event_file, random_events


def test_format_events_matches_printf():
    ev = random_events(500)
    expected = "".join(f"{e['t']:.9f} {e['x']} {e['y']} {e['p']}\n" for e in ev)
    assert format_events(ev).decode() == expected


def test_round_trip_through_text_and_cache(tmp_path):
    ev = random_events(50_000, seed=1)
    path = tmp_path / "events.txt"
    write_events_text(path, ev, 240, 180)  # primes the cache
    primed = load_event_file(path)
    os.unlink(cache_path(cache_key("text", *file_identity(path), 240, 180, 1e-6, 0.0)))
    parsed = load_event_file(path)  # parsed from text this time
    assert isinstance(parsed, np.memmap)
    np.testing.assert_array_equal(parsed, primed)  # the primed cache equals a fresh parse, bit for bit
    np.testing.assert_array_equal(parsed[["x", "y", "p"]], ev[["x", "y", "p"]])
    np.testing.assert_allclose(parsed["t"], ev["t"], atol=1e-9)
