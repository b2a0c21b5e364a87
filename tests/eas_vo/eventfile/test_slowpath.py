"""The text path of event files: `#` comment lines are skipped wherever they are, as in every
other table, and a bad line is still named by its line in the file."""

import numpy as np
import pytest

from eas_vo.errors import DataError
from helpers import load_event_file, random_events


def _text(events) -> bytes:
    from eas_vo.eventfile.text import format_events

    return format_events(events)


def test_a_header_and_comments_anywhere_are_skipped(tmp_path):
    events = random_events(3000, seed=4)
    body = _text(events).splitlines(keepends=True)
    path = tmp_path / "events.txt"
    path.write_bytes(b"# t x y p\n" + b"".join(body[:1000]) + b"  # a note\n" + b"".join(body[1000:]) + b"#\n")
    loaded = load_event_file(path)
    np.testing.assert_array_equal(loaded["x"], events["x"])
    np.testing.assert_allclose(loaded["t"], events["t"], atol=1e-9)


def test_a_bad_line_after_a_header_is_named_by_its_file_line(tmp_path):
    body = _text(random_events(50, seed=5)).splitlines(keepends=True)
    path = tmp_path / "events.txt"
    path.write_bytes(b"# t x y p\n" + b"".join(body[:20]) + b"0.5 1 2\n" + b"".join(body[20:]))
    with pytest.raises(DataError, match=r"events.txt:22: expected 4 columns"):
        load_event_file(path)


def test_a_byte_order_mark_and_crlf_line_ends_are_read_past(tmp_path):
    events = random_events(500, seed=6)
    path = tmp_path / "events.txt"
    path.write_bytes(b"\xef\xbb\xbf" + _text(events).replace(b"\n", b"\r\n"))
    np.testing.assert_array_equal(load_event_file(path)["y"], events["y"])
