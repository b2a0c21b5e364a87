"""Loading event text through the cache: invalidation, errors naming file and line, lenient drops, clamping."""

import os

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.errors import DataError, DataWarnings
from helpers import hostile_settings, load_event_file


def test_cache_is_invalidated_when_the_file_changes(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n")
    assert len(load_event_file(path)) == 2
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n0.3 5 6 1\n")
    os.utime(path, ns=(1, 2))
    assert len(load_event_file(path)) == 3


def test_a_rewrite_with_the_old_size_and_mtime_is_seen(tmp_path):
    """Same size, mtime put back (touch -r): the change time and the content sample differ."""
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 3 4 0\n")
    before = os.stat(path)
    assert load_event_file(path)["x"].tolist() == [1, 3]
    path.write_text("0.1 7 2 1\n0.2 3 4 0\n")  # x 1 -> 7, same size
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert load_event_file(path)["x"].tolist() == [7, 3]


def cached_file(path):
    from eas_vo.eventfile import cache_key, cache_path, file_identity

    return cache_path(cache_key("text", *file_identity(path), 240, 180, 1e-6, 0.0))


@given(st.data())
@hostile_settings(max_examples=60)
def test_a_damaged_cache_is_detected_and_rebuilt(tmp_path, data):
    """Random damage to the cache file (flipped bits anywhere, a cut, bytes appended): the
    next load gives exactly the events of the text, rebuilding the cache when it saw damage."""
    path = tmp_path / "events.txt"
    if not path.exists():
        from eas_vo.eventfile import write_events_text
        from helpers import random_events

        write_events_text(path, random_events(3000, seed=5), 240, 180)
    clean = np.array(load_event_file(path))
    cache = cached_file(path)
    raw = bytearray(cache.read_bytes())
    kind = data.draw(st.sampled_from(["flip", "cut", "append"]))
    if kind == "flip":
        for offset in data.draw(st.lists(st.integers(0, len(raw) - 1), min_size=1, max_size=20)):
            raw[offset] ^= 1 << data.draw(st.integers(0, 7))
    elif kind == "cut":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    else:
        raw += bytes(data.draw(st.integers(1, 40)))
    cache.write_bytes(bytes(raw))
    np.testing.assert_array_equal(load_event_file(path), clean)


def test_opposite_flips_of_one_bit_in_two_records_are_detected(tmp_path):
    """The damage a sum of 64-bit words misses: one bit set in one record and the same bit of
    the same word lane cleared in another (the sum is unchanged, as the test checks). The
    checksum must catch it and the cache be rebuilt."""
    from eas_vo.eventfile import write_events_text
    from eas_vo.eventfile.cache import HEADER_BYTES
    from helpers import random_events

    path = tmp_path / "events.txt"
    write_events_text(path, random_events(3000, seed=5), 240, 180)
    clean = np.array(load_event_file(path))
    cache = cached_file(path)
    raw = bytearray(cache.read_bytes())
    bit = 0x10
    first = HEADER_BYTES + 8 * 101 + 3  # a byte whose bit is clear, and one 8k bytes on whose bit is set
    first = next(i for i in range(first, len(raw) - 8, 8) if not raw[i] & bit)
    second = next(i for i in range(first + 8, len(raw), 8) if raw[i] & bit)

    def word_sum(data):
        body = np.frombuffer(bytes(data[HEADER_BYTES:]), np.uint8)
        return int(body[: len(body) // 8 * 8].view("<u8").sum(dtype=np.uint64))

    before = word_sum(raw)
    raw[first] |= bit
    raw[second] &= ~bit & 0xFF
    assert word_sum(raw) == before
    cache.write_bytes(bytes(raw))
    np.testing.assert_array_equal(load_event_file(path), clean)


@pytest.mark.parametrize("damage", ["{not json", "[1,2,3]", b"\xff\xfe", None])
def test_a_lenient_caches_missing_or_damaged_warnings_rebuild_it(tmp_path, damage):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 300 4 0\n0.3 5 6 1\n")
    first = DataWarnings()
    load_event_file(path, lenient=True, warnings=first)
    from eas_vo.eventfile import cache_key, cache_path, file_identity

    key = cache_key("text", *file_identity(path), 240, 180, 1e-6, 0.0)
    sidecar = cache_path(key).with_name(cache_path(key).stem + "-lenient.warnings")
    assert sidecar.exists()
    if damage is None:
        sidecar.unlink()
    else:
        sidecar.write_bytes(damage if isinstance(damage, bytes) else damage.encode())
    again = DataWarnings()
    assert len(load_event_file(path, lenient=True, warnings=again)) == 2
    assert again.lines() == first.lines()  # the dropped line is reported again, not forgotten


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
        load_event_file(path)
    assert info.value.line == line and str(info.value).startswith(f"{path}:{line}:")


@pytest.mark.parametrize("text,line,message", BAD)
def test_lenient_drops_and_counts(tmp_path, text, line, message):
    path = tmp_path / "events.txt"
    path.write_text(text)
    warnings = DataWarnings()
    events = load_event_file(path, lenient=True, warnings=warnings)
    assert len(events) == text.count("\n") + (not text.endswith("\n")) - 1
    (report,) = warnings.lines()
    assert "1 dropped" in report and f"(first at line {line})" in report
    again = DataWarnings()
    load_event_file(path, lenient=True, warnings=again)  # from the cache: the warning is reported again
    assert again.lines() == warnings.lines()
    with pytest.raises(DataError):
        load_event_file(path)  # the lenient cache never serves a strict read


def test_small_steps_back_within_tolerance_are_clamped(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2000000 3 4 0\n0.1999995 5 6 1\n0.3 1 1 1\n")
    t = load_event_file(path)["t"]
    np.testing.assert_array_equal(t, [0.1, 0.2, 0.2, 0.3])
    with pytest.raises(DataError, match="goes backwards"):
        load_event_file(path, tolerance_s=1e-7)


def test_strict_reports_the_earliest_bad_line_whatever_its_problem(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.1 1 2 1\n0.2 3 4 5\n0.3 999 4 1\n")  # line 2: polarity, line 3: off the sensor
    with pytest.raises(DataError, match="polarity") as info:
        load_event_file(path)
    assert info.value.line == 2
    warnings = DataWarnings()
    assert len(load_event_file(path, lenient=True, warnings=warnings)) == 1
    assert sorted(warnings.lines()) == sorted(
        [
            f"{path}: 1 dropped: polarity not 0/1 (or -1/1) (first at line 2)",
            f"{path}: 1 dropped: pixel outside the 240x180 sensor (first at line 3)",
        ]
    )


def test_the_checksum_taken_while_writing_is_the_records_checksum(tmp_path):
    """build_cache hashes records as they are written, in pieces of any size: the header holds
    the XXH3-64 of all the records at once, and the cache maps back to what was written."""
    from eas_vo.eventfile.cache import HEADER_BYTES, build_cache, open_cache, records_checksum
    from eas_vo.types import EVENT_DTYPE

    rng = np.random.default_rng(3)
    events = np.zeros(10_007, EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = np.sort(rng.random(10_007)), rng.integers(0, 240, 10_007), 7, 1

    def fill(out):
        out.write(events[:5].data)
        out.writelines([events[5:4000].data, events[4000:].data])
        return len(events)

    built = build_cache(tmp_path / "c.ev", fill)
    header = (tmp_path / "c.ev").read_bytes()[:HEADER_BYTES]
    assert int.from_bytes(header[16:24], "little") == records_checksum(events.tobytes())
    assert built.tobytes() == events.tobytes()
    assert open_cache(tmp_path / "c.ev").tobytes() == events.tobytes()


def test_write_behind_writes_in_order_and_names_the_earlier_problem_first():
    """Blocks are written in order; when the reading fails after a block whose check fails,
    the block's own error (the earlier event) is the one raised."""
    import io

    from eas_vo.eventfile import write_behind
    from eas_vo.types import EVENT_DTYPE

    def block(k):
        events = np.zeros(3, EVENT_DTYPE)
        events["t"] = k
        return lambda: events

    out = io.BytesIO()
    assert write_behind(out, (block(k) for k in range(5))) == 15
    assert np.array_equal(np.frombuffer(out.getvalue(), EVENT_DTYPE)["t"], np.repeat(np.arange(5.0), 3))

    def bad_check():
        raise DataError("f", "bad pixel", 2)

    def blocks():
        yield block(0)
        yield bad_check
        raise DataError("f", "unreadable", 9)

    with pytest.raises(DataError, match="bad pixel"):
        write_behind(io.BytesIO(), blocks())


def test_validator_divides_integer_ticks_as_numpy_does():
    """Microsecond ticks in the library's own dtypes (int64 times, int16 pixels, int8
    polarity, strided fields of one record array) give the records of seconds computed by
    numpy, on the fast path and on the row-by-row path (a bad row dropped)."""
    from eas_vo.errors import DataWarnings
    from eas_vo.eventfile import Validator

    raw = np.zeros(6, [("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
    raw["timestamp"] = [1_000_001, 1_333_333, 2_718_281, 3_141_592, 9_999_999, 12_345_678]
    raw["x"], raw["y"], raw["polarity"] = [0, 5, 239, 17, 300, 3], [0, 179, 1, 2, 3, 4], [0, 1, 1, 0, 1, 0]
    seconds = raw["timestamp"] / 1e6
    valid = raw[[0, 1, 2, 3, 5]]  # (x = 300 is off the sensor)
    assert not valid["x"].flags.c_contiguous
    fast = Validator("f", 240, 180, 1e-6, False, DataWarnings())(
        valid["timestamp"], valid["x"], valid["y"], valid["polarity"], lambda i: i, per_second=1e6
    )
    assert np.array_equal(fast["t"], seconds[[0, 1, 2, 3, 5]])
    assert np.array_equal(fast["x"], valid["x"]) and np.array_equal(fast["p"], valid["polarity"])
    warnings = DataWarnings()
    slow = Validator("f", 240, 180, 1e-6, True, warnings)(
        raw["timestamp"], raw["x"], raw["y"], raw["polarity"], lambda i: i, per_second=1e6
    )
    assert slow.tobytes() == fast.tobytes()
    assert sum(warnings.counts.values()) == 1


@hostile_settings(120)
@given(st.data())
def test_the_block_check_agrees_with_row_by_row_verdicts(data):
    """check_and_pack's branch-free block pass (with its row-by-row redo) against _accept row by
    row in Python: the same first bad row, last time and records, with damage near block edges
    (bad pixels and polarities, NaN, steps back within and beyond the tolerance)."""
    from eas_vo.eventfile.kernels import TABLE_CHUNK_ROWS, _accept, check_and_pack
    from eas_vo.types import EVENT_DTYPE

    n = data.draw(st.integers(1, 3 * TABLE_CHUNK_ROWS))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    ticks = np.cumsum(rng.integers(0, 50, n)) + 10_000_000
    x, y, p = rng.integers(0, 240, n), rng.integers(0, 180, n), rng.integers(0, 2, n)
    ticks = ticks.astype(float)
    for _ in range(data.draw(st.integers(0, 4))):
        i = data.draw(
            st.sampled_from(
                [
                    0,
                    n - 1,
                    min(n - 1, TABLE_CHUNK_ROWS),
                    min(n - 1, TABLE_CHUNK_ROWS - 1),
                    data.draw(st.integers(0, n - 1)),
                ]
            )
        )
        kind = data.draw(st.sampled_from(["x", "y", "p", "nan", "back_small", "back_big"]))
        if kind == "x":
            x[i] = data.draw(st.sampled_from([-1, 240, 5000]))
        elif kind == "y":
            y[i] = data.draw(st.sampled_from([-1, 180]))
        elif kind == "p":
            p[i] = data.draw(st.sampled_from([-2, 2]))
        elif kind == "nan":
            ticks[i] = np.nan
        else:
            ticks[i] -= 0.5 if kind == "back_small" else 5000
    last_t = data.draw(st.sampled_from([-np.inf, 9.0, 10.0000005]))
    events = np.zeros(n, EVENT_DTYPE)
    bad, got_last = check_and_pack(ticks, 1e6, x, y, p, last_t, 240, 180, 1e-6, events)
    expected = np.zeros(n, EVENT_DTYPE)
    want_bad, t_last = -1, last_t
    for i in range(n):
        ok, t = _accept.py_func(ticks[i] / 1e6, x[i], y[i], p[i], t_last, 240, 180, 1e-6)
        if not ok:
            want_bad = i
            break
        t_last = t
        expected[i] = (t, x[i], y[i], p[i] > 0)
    assert (bad, got_last) == (want_bad, t_last)
    kept = n if bad < 0 else bad
    assert events[:kept].tobytes() == expected[:kept].tobytes()


@hostile_settings(120)
@given(st.data())
def test_the_dv_record_check_agrees_with_the_field_check(data):
    """check_and_pack_dv on DV's 16-byte Event records as int64 word pairs against
    check_and_pack on the records' fields: the same first bad row, last time and records, with
    pixels negative or beyond the sensor (also beyond int16's 32767 as unsigned), polarity bytes
    above 1, steps back within and beyond the tolerance, near block edges."""
    from eas_vo.datasets.aedat4_packets import PACKET_EVENT
    from eas_vo.eventfile.kernels import TABLE_CHUNK_ROWS, check_and_pack, check_and_pack_dv
    from eas_vo.types import EVENT_DTYPE

    n = data.draw(st.integers(1, 3 * TABLE_CHUNK_ROWS))
    width, height = data.draw(st.sampled_from([(240, 180), (346, 260), (40000, 40000)]))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    records = np.zeros(n, PACKET_EVENT)
    records["t"] = np.cumsum(rng.integers(0, 50, n)) + 10_000_000
    records["x"], records["y"] = rng.integers(0, min(width, 32767), n), rng.integers(0, min(height, 32767), n)
    records["p"] = rng.integers(0, 2, n)
    for _ in range(data.draw(st.integers(0, 4))):
        i = data.draw(
            st.sampled_from(
                [
                    0,
                    n - 1,
                    min(n - 1, TABLE_CHUNK_ROWS),
                    min(n - 1, TABLE_CHUNK_ROWS - 1),
                    data.draw(st.integers(0, n - 1)),
                ]
            )
        )
        kind = data.draw(st.sampled_from(["x", "y", "p", "back_small", "back_big"]))
        if kind in ("x", "y"):
            records[kind][i] = data.draw(st.sampled_from([-1, -32768, min(width, 32767), min(height, 32767), 32767]))
        elif kind == "p":
            records["p"][i] = data.draw(st.integers(2, 255))
        else:
            records["t"][i] -= 1 if kind == "back_small" else 5000
    last_t = data.draw(st.sampled_from([-np.inf, 9.0, 10.0000005]))
    want = np.zeros(n, EVENT_DTYPE)
    want_bad, want_last = check_and_pack(
        records["t"], 1e6, records["x"], records["y"], records["p"], last_t, width, height, 1e-6, want
    )
    got = np.zeros(n, EVENT_DTYPE)
    bad, got_last = check_and_pack_dv(records.view(np.int64).reshape(-1, 2), 0, last_t, width, height, 1e-6, got)
    assert (bad, got_last) == (want_bad, want_last)
    kept = n if bad < 0 else bad
    assert got[:kept].tobytes() == want[:kept].tobytes()
