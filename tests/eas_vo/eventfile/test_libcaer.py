"""iniVation's `libcaer` and `libcaer_cmp` packets: events written by the encoders below (every
word kind) come back exactly, the real DAVIS346 bag gives event_camera_py's stated sums, and
damaged bytes are a ValueError naming the byte, never a crash."""

import re

import numpy as np
import pytest

from eas_vo.eventfile.libcaer import LibcaerCmpDecoder, LibcaerDecoder
from helpers import SHARED_DATA, require

#: A host clock at Unix time [ns] (its last digits not zero: nothing may round them).
HOST_NS = 1_744_227_144_123_456_789
TEST_EVENTS_2 = SHARED_DATA / "real_files" / "event_camera_py" / "test_events_2"
SIZES = [(346, 260), (640, 480), (1280, 720)]


def random_events(n: int, width: int, height: int, seed: int, step_us: int = 3):
    """n events (sensor time [us] from 0; x, y; p) on a width x height sensor, ordered by time,
    x, p and y, many sharing a time and a column (so libcaer_cmp packs them into vectors)."""
    rng = np.random.default_rng(seed)
    t_us = np.cumsum(rng.integers(0, step_us, n) * (rng.random(n) < 0.3))
    x = np.where(rng.random(n) < 0.5, rng.integers(0, width, n), width // 2).astype(np.int64)
    y = np.where(rng.random(n) < 0.5, rng.integers(0, height, n), rng.integers(height - 8, height, n)).astype(np.int64)
    p = rng.integers(0, 2, n)
    order = np.lexsort((y, p, x, t_us))
    return t_us[order], x[order], y[order], p[order]


def encode_libcaer(t_us, x, y, p, valid=None) -> tuple[bytes, int]:
    """Events at sensor times t_us [us] after the host start HOST_NS -> (`libcaer` bytes,
    time_base [ns]): libcaer's 31-bit timestamps, the bits above them in the time base."""
    t_us = np.asarray(t_us, np.int64)
    valid = np.ones(len(t_us), np.int64) if valid is None else np.asarray(valid, np.int64)
    words = np.empty((len(t_us), 2), "<u4")
    words[:, 0] = valid | (np.asarray(p) << 1) | (np.asarray(y) << 2) | (np.asarray(x) << 17)
    words[:, 1] = t_us & ((1 << 31) - 1)
    return words.tobytes(), HOST_NS + (int(t_us[0]) >> 31 << 31) * 1000


def encode_cmp(t_us, x, y, p) -> tuple[bytes, int]:
    """Events (as in encode_libcaer) -> (`libcaer_cmp` bytes, time_base [ns]): every run of
    events with one time, x, polarity and y // 8 is one ADDR_Y or VECT_BASE_Y + VECT_8."""
    dt = np.asarray(t_us, np.int64) - int(t_us[0])
    words, now, column = [], (0, 0), None
    keys = list(zip(dt.tolist(), np.asarray(x).tolist(), np.asarray(p).tolist(), (np.asarray(y) // 8).tolist()))
    i = 0
    while i < len(keys):
        j = i
        while j < len(keys) and keys[j] == keys[i]:
            j += 1
        d, ex, pol, block = keys[i]
        if d >> 12 != now[0]:
            words.append(0 << 12 | d >> 12)
        if d & 0xFFF != now[1]:
            words.append(1 << 12 | d & 0xFFF)
        now = (d >> 12, d & 0xFFF)
        if ex != column:
            words.append(2 << 12 | ex)
            column = ex
        ys = sorted(set(np.asarray(y)[i:j].tolist()))
        if len(ys) != j - i:
            raise ValueError("an event repeated at one time and pixel cannot be encoded")
        if len(ys) == 1:
            words.append(3 << 12 | pol << 11 | ys[0])
        else:
            words += [4 << 12 | pol << 11 | block * 8, 5 << 12 | sum(1 << (v - block * 8) for v in ys)]
        i = j
    return np.array(words, "<u2").tobytes(), HOST_NS + int(t_us[0]) * 1000


def unique_pixels_per_time(t_us, x, y, p):
    """The events with each (time, x, y) once (a pixel fires once per microsecond)."""
    _, keep = np.unique(np.column_stack([t_us, x, y]), axis=0, return_index=True)
    keep = np.sort(keep)
    return t_us[keep], x[keep], y[keep], p[keep]


def packets(t_us, x, y, p, n_packets: int):
    """The events split into n_packets consecutive chunks."""
    for chunk in np.array_split(np.arange(len(t_us)), n_packets):
        yield t_us[chunk], x[chunk], y[chunk], p[chunk]


def assert_events(decoded, t_us, x, y, p):
    np.testing.assert_array_equal(decoded.t_ns, HOST_NS + np.asarray(t_us, np.int64) * 1000)
    np.testing.assert_array_equal(decoded.x, x)
    np.testing.assert_array_equal(decoded.y, y)
    np.testing.assert_array_equal(decoded.p, p)
    assert (decoded.t_ns.dtype, decoded.x.dtype, decoded.y.dtype, decoded.p.dtype) == (
        np.int64,
        np.uint16,
        np.uint16,
        np.uint8,
    )
    assert len(decoded.trigger_t_ns) == len(decoded.trigger_edge) == len(decoded.trigger_id) == 0


def word_codes(data: bytes) -> set[int]:
    return set((np.frombuffer(data, "<u2") >> 12).tolist())


# ----------------------------------------------------------------------------- known answers


@pytest.mark.parametrize("width, height", SIZES)
def test_libcaer_events_come_back_exactly_across_a_roll_over_with_invalid_events_skipped(width, height):
    t_us, x, y, p = random_events(3000, width, height, seed=width, step_us=10)
    t_us = t_us + (1 << 31) - t_us[1500]  # the 31-bit timestamp rolls over inside the second packet
    valid = np.random.default_rng(1).random(len(t_us)) < 0.9
    decoder = LibcaerDecoder(width, height)
    rolled = 0
    for chunk, keep in zip(packets(t_us, x, y, p, 3), np.array_split(valid, 3)):
        data, time_base = encode_libcaer(*chunk, valid=keep)
        rolled += int(np.any(np.diff(chunk[0] & ((1 << 31) - 1)) < 0))
        decoded = decoder.decode(np.frombuffer(data, np.uint8), time_base)
        assert_events(decoded, *(column[keep] for column in chunk))
    assert rolled == 1


@pytest.mark.parametrize("width, height", SIZES)
def test_libcaer_cmp_events_come_back_exactly_with_every_word_kind(width, height):
    events = unique_pixels_per_time(*random_events(20000, width, height, seed=height, step_us=40))
    decoder = LibcaerCmpDecoder(width, height)
    seen = set()
    for chunk in packets(*events, 4):
        data, time_base = encode_cmp(*chunk)
        seen |= word_codes(data)
        assert_events(decoder.decode(np.frombuffer(data, np.uint8), time_base), *chunk)
    assert seen == {0, 1, 2, 3, 4, 5}  # TIME_HIGH, TIME_LOW, ADDR_X, ADDR_Y, VECT_BASE_Y, VECT_8


def cmp_words(*words) -> np.ndarray:
    return np.array(words, "<u2").view(np.uint8)


ADDR_X_5, ADDR_X_7, ADDR_Y_3_ON, BASE_Y_16_OFF, VECT_8_BITS_0_2 = (
    2 << 12 | 5,
    2 << 12 | 7,
    3 << 12 | 1 << 11 | 3,
    4 << 12 | 16,
    5 << 12 | 0b101,
)


def test_libcaer_cmp_carries_the_address_to_the_next_packet_but_not_from_a_damaged_one():
    decoder = LibcaerCmpDecoder(346, 260)
    decoder.decode(cmp_words(ADDR_X_5, BASE_Y_16_OFF), 0)
    with pytest.raises(ValueError, match=r"byte 2: word code 9"):
        decoder.decode(cmp_words(ADDR_X_7, 9 << 12), 0)
    decoded = decoder.decode(cmp_words(1 << 12 | 7, VECT_8_BITS_0_2, ADDR_Y_3_ON), 1000)
    assert decoded.x.tolist() == [5, 5, 5] and decoded.y.tolist() == [16, 18, 3] and decoded.p.tolist() == [0, 0, 1]
    assert decoded.t_ns.tolist() == [8000] * 3  # time_base + 7 us; the time restarts at 0 in each packet


# ----------------------------------------------------------------------------- the real bag


def test_the_real_davis346_bag_gives_event_camera_pys_stated_sums():
    """event_camera_py's tests/test_2.py: 360223 OFF and 211043 ON events, no triggers, and 335555680277 as
    the sum of the event times [us]; its accumulator keeps each time relative to the first event's
    (accumulator.h, shorten_time), which is the sum that matches (the wrapped uint64 sum of absolute times is not)."""
    folder = require(TEST_EVENTS_2)
    from rosbags.rosbag2 import Reader

    from eas_vo.datasets.rosbag2 import bag_typestore

    path = folder / "test_events_2_0.mcap"
    decoded, first_time_base = [], None
    with Reader(path) as reader:
        store = bag_typestore(path, reader.connections)
        decoder = None
        for connection, _, raw in reader.messages():
            msg = store.deserialize_cdr(raw, connection.msgtype)
            assert msg.encoding == "libcaer_cmp"
            decoder = decoder or LibcaerCmpDecoder(msg.width, msg.height)
            first_time_base = first_time_base or msg.time_base
            decoded.append(decoder.decode(msg.events, msg.time_base))
    assert (decoder.width, decoder.height, len(decoded)) == (346, 260, 100)
    t_ns = np.concatenate([d.t_ns for d in decoded])
    p = np.concatenate([d.p for d in decoded])
    assert (np.count_nonzero(p == 0), np.count_nonzero(p == 1)) == (360223, 211043)
    assert sum(len(d.trigger_t_ns) for d in decoded) == 0
    t_us = t_ns // 1000
    assert t_us[0] == first_time_base // 1000 == 1744227144732712  # event_camera_py's first sensor time
    assert int(np.sum(t_us - t_us[0])) == 335555680277
    assert np.all(np.diff(t_ns) >= 0)


# ----------------------------------------------------------------------------- damaged bytes


def offset_named(exc: pytest.ExceptionInfo) -> int:
    found = re.search(r"byte (\d+)", str(exc.value))
    assert found, f"no byte offset in {exc.value}"
    return int(found.group(1))


@pytest.mark.parametrize(
    "words, offset, what",
    [
        ((ADDR_X_5, 6 << 12), 2, "VECT_12, which libcaer_driver does not write"),
        ((ADDR_X_5, 15 << 12 | 0xFFF), 2, "word code 15"),
        ((1 << 12 | 4, ADDR_Y_3_ON), 2, "ADDR_Y event before any ADDR_X"),
        ((ADDR_X_5, VECT_8_BITS_0_2), 2, "VECT_8 event before any VECT_BASE_Y"),
        ((2 << 12 | 346, ADDR_Y_3_ON), 2, "x=346, y=3 outside the 346x260 sensor"),
        ((ADDR_X_5, 4 << 12 | 248, 5 << 12 | 0x80, 5 << 12 | 0x10), 6, "x=5, y=260 outside"),
        ((1 << 12 | 9, ADDR_X_5, ADDR_Y_3_ON, 1 << 12 | 8, ADDR_Y_3_ON), 8, "steps back from 9 us to 8 us"),
    ],
)
def test_damaged_libcaer_cmp_words_are_named_by_their_byte(words, offset, what):
    with pytest.raises(ValueError, match=re.escape(what)) as exc:
        LibcaerCmpDecoder(346, 260).decode(cmp_words(*words), HOST_NS)
    assert offset_named(exc) == offset


def libcaer_words(*pairs) -> np.ndarray:
    return np.array(pairs, "<u4").view(np.uint8)


@pytest.mark.parametrize(
    "pairs, offset, what",
    [
        (((1 | 3 << 17, 10), (1, 1 << 31)), 12, "has bit 31 set"),
        (((1, 10), (1, 10 + (1 << 30))), 12, "time jumps from 10 us to 1073741834 us"),
        (((1, 10), (1, 9)), 12, "time jumps from 10 us to 9 us"),
        (((1, 5), (1 | 346 << 17, 6)), 8, "x=346, y=0 outside the 346x260 sensor"),
        (((1 | 260 << 2, 5),), 0, "x=0, y=260 outside"),
    ],
)
def test_damaged_libcaer_events_are_named_by_their_byte(pairs, offset, what):
    with pytest.raises(ValueError, match=re.escape(what)) as exc:
        LibcaerDecoder(346, 260).decode(libcaer_words(*pairs), HOST_NS)
    assert offset_named(exc) == offset


@pytest.mark.parametrize("decoder, word", [(LibcaerDecoder, 8), (LibcaerCmpDecoder, 2)])
def test_cut_packets_name_the_byte_where_the_last_word_breaks_off(decoder, word):
    t_us, x, y, p = unique_pixels_per_time(*random_events(500, 346, 260, seed=3))
    data, time_base = (encode_libcaer if word == 8 else encode_cmp)(t_us, x, y, p)
    for cut in range(1, word):
        with pytest.raises(ValueError, match=rf"cut inside a word \(\d+ bytes, not a multiple of {word}\)") as exc:
            decoder(346, 260).decode(np.frombuffer(data[: len(data) - cut], np.uint8), time_base)
        assert offset_named(exc) == (len(data) - cut) // word * word


@pytest.mark.parametrize(
    "decoder, span_ns", [(LibcaerDecoder, (1 << 31) * 1000), (LibcaerCmpDecoder, (1 << 24) * 1000)]
)
def test_a_time_base_that_leaves_no_room_for_the_packets_times_is_refused(decoder, span_ns):
    for time_base in (-1, np.iinfo(np.int64).max - span_ns + 1):
        with pytest.raises(ValueError, match="time_base"):
            decoder(346, 260).decode(np.zeros(8, np.uint8), time_base)


def test_libcaer_time_roll_overs_that_would_leave_int64_are_refused():
    near_end = np.iinfo(np.int64).max - (1 << 31) * 1000
    pairs = [(1, (1 << 31) - 1), (1, 5)]
    with pytest.raises(ValueError, match="byte 12: event time beyond the int64"):
        LibcaerDecoder(346, 260).decode(libcaer_words(*pairs), near_end)


@pytest.mark.parametrize("decoder", [LibcaerDecoder, LibcaerCmpDecoder])
def test_random_bytes_and_flipped_bits_decode_or_name_a_byte_inside_the_packet(decoder):
    """Seeded random packets, and real-looking packets with bits flipped: each either decodes to
    events inside the sensor or is a ValueError naming a word's offset in the packet."""
    rng = np.random.default_rng(38)
    t_us, x, y, p = unique_pixels_per_time(*random_events(2000, 346, 260, seed=4))
    clean, time_base = (encode_libcaer if decoder is LibcaerDecoder else encode_cmp)(t_us, x, y, p)
    word = 8 if decoder is LibcaerDecoder else 2
    refused = 0
    for trial in range(400):
        if trial % 2:
            data = rng.integers(0, 256, rng.integers(0, 50) * word, dtype=np.uint8)
        else:
            data = np.frombuffer(clean, np.uint8).copy()
            at = rng.integers(0, len(data), 3)
            data[at] ^= (1 << rng.integers(0, 8, 3)).astype(np.uint8)
        try:
            decoded = decoder(346, 260).decode(data, time_base)
        except ValueError as exc:
            offset = int(re.search(r"byte (\d+)", str(exc)).group(1))
            assert 0 <= offset < len(data) and offset % word in (0, 4), exc
            refused += 1
            continue
        assert np.all(decoded.x < 346) and np.all(decoded.y < 260) and np.all(decoded.t_ns >= time_base)
    assert 0 < refused < 400


@pytest.mark.parametrize("decoder", [LibcaerDecoder, LibcaerCmpDecoder])
def test_a_large_damaged_packet_is_refused_with_its_offset(decoder):
    """8 MB of zero words (libcaer: invalid events at one time; libcaer_cmp: TIME_HIGH 0) ending in a
    bad word (libcaer: a timestamp's bit 31; libcaer_cmp: word code 8) are refused at that word."""
    data = np.zeros(8 << 20, np.uint8)
    data[-1] = 0x80
    with pytest.raises(ValueError) as exc:
        decoder(346, 260).decode(data, HOST_NS)
    assert offset_named(exc) == len(data) - (4 if decoder is LibcaerDecoder else 2)
