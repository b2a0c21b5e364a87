"""Prophesee's EVT 3.0 / 2.0 / 2.1 decoders: known answers from an independent encoder (vectors,
roll-overs, triggers, monitoring words), the reference decoders' time rules, events outside the
sensor, damaged input, and the real EVT 3.0 packets of event_camera_py's test bag against the
sums that project states for them."""

from __future__ import annotations

import numpy as np
import pytest
from prophesee_words import (
    encode_evt2,
    encode_evt3,
    encode_evt21,
    event_camera_py_packets,
    random_stream,
    random_triggers,
)

from eas_vo.eventfile.prophesee import OUTSIDE_REFUSED_MIN, Evt2Decoder, Evt3Decoder, Evt21Decoder, WordError

W, H = 640, 480

#: (decoder of a sensor size, encoder, time [us] the stream starts at: a roll-over just ahead)
FORMATS = {
    "evt3": (Evt3Decoder, encode_evt3, (1 << 24) - 150_000),
    "evt2": (Evt2Decoder, encode_evt2, (1 << 34) - 150_000),
    "evt21": (Evt21Decoder, encode_evt21, (1 << 34) - 150_000),
    "evt21-legacy": (
        lambda w, h: Evt21Decoder(w, h, legacy=True),
        lambda e, t: encode_evt21(e, t, legacy=True),
        (1 << 34) - 150_000,
    ),
}


def decode_all(decoder, words, cuts=()):
    """The words decoded in packets cut at word indices `cuts`, joined."""
    bounds = [0, *cuts, len(words)]
    parts = [decoder.decode(words[a:b].view(np.uint8), 0) for a, b in zip(bounds, bounds[1:])]
    return {
        name: np.concatenate([getattr(d, name) for d in parts])
        for name in ("t_ns", "x", "y", "p", "trigger_t_ns", "trigger_edge", "trigger_id")
    }


def assert_decoded(got, events, triggers):
    assert len(got["t_ns"]) == len(events)
    np.testing.assert_array_equal(got["t_ns"], events["t"] * 1000)
    for name in ("x", "y", "p"):
        np.testing.assert_array_equal(got[name], events[name])
    np.testing.assert_array_equal(got["trigger_t_ns"], triggers["t"] * 1000)
    np.testing.assert_array_equal(got["trigger_edge"], triggers["edge"])
    np.testing.assert_array_equal(got["trigger_id"], triggers["id"])


@pytest.mark.parametrize("name", FORMATS)
def test_encoded_streams_decode_to_exactly_their_events_across_a_roll_over(name):
    """Rows of neighbours (vectors), trigger edges on two channels, OTHERS/CONTINUED words, and
    the time's roll-over 150 ms in: every event and trigger back, in the words' order, whole or
    cut into packets anywhere (the state carried)."""
    make, encode, t0 = FORMATS[name]
    events = random_stream(30_000, W, H, seed=2, t0_us=t0, span_us=400_000)
    triggers = random_triggers(40, t0, 400_000)
    words, expected, expected_triggers = encode(events, triggers)
    assert expected["t"].max() > t0 + 150_000 and len(expected) == len(events)
    assert_decoded(decode_all(make(W, H), words), expected, expected_triggers)
    cuts = np.sort(np.random.default_rng(0).choice(np.arange(1, len(words)), 25, replace=False))
    decoder = make(W, H)
    assert_decoded(decode_all(decoder, words, cuts), expected, expected_triggers)
    assert decoder.outside == 0 and decoder.skipped == 0


def test_an_evt3_time_high_a_little_back_is_a_glitch_and_far_back_a_roll_over():
    """event_camera_codecs' rule: back by at most 10 units (of 4096 us) the time goes back with
    it; back by more, the 24-bit time has rolled over."""
    y, x = 0x0000 | 7, 0x2000 | 5

    def th(v):
        return 0x8000 | v

    def tl(v):
        return 0x6000 | v

    words = np.array([th(100), tl(3), y, x, th(90), tl(4), x, th(79), tl(5), x], np.uint16)  # back 10, then 11
    got = Evt3Decoder(W, H).decode(words.view(np.uint8))
    np.testing.assert_array_equal(got.t_ns // 1000, [100 << 12 | 3, 90 << 12 | 4, (1 << 24) + (79 << 12 | 5)])


@pytest.mark.parametrize("name", FORMATS)
def test_events_before_the_first_time_are_skipped_and_counted(name):
    make, encode, t0 = FORMATS[name]
    events = random_stream(200, W, H, seed=4, t0_us=1000, span_us=5000)
    words, expected, _ = encode(events, None)
    timed = np.flatnonzero([_is_time(name, int(w)) for w in words])
    first_event = int(np.flatnonzero([not _is_time(name, int(w)) for w in words])[0])
    # the stream without its first time words: events until the next time (high, for EVT 3.0) are skipped
    cut = words[np.setdiff1d(np.arange(len(words)), timed[timed < first_event])]
    decoder = make(W, H)
    got = decoder.decode(cut.view(np.uint8))
    assert decoder.skipped > 0 and len(got.t_ns) + decoder.skipped == len(expected)
    np.testing.assert_array_equal(got.t_ns, expected["t"][decoder.skipped :] * 1000)


def _is_time(name: str, word: int) -> bool:
    if name == "evt3":
        return word >> 12 in (0x8, 0x6)
    if name == "evt21-legacy":
        return (word & 0xFFFFFFFF) >> 28 == 0x8
    return word >> (60 if name == "evt21" else 28) == 0x8


@pytest.mark.parametrize("name", FORMATS)
def test_events_outside_the_sensor_are_dropped_and_counted_and_many_refused(name):
    make, encode, _ = FORMATS[name]
    events = random_stream(2000, W, H, seed=5, t0_us=1000, span_us=50_000, runs=False)
    events["x"][:3] = W + 10  # a few strays: dropped and counted (as Prophesee's decoders drop them)
    words, expected, _ = encode(events, None)
    inside = expected["x"] < W
    decoder = make(W, H)
    got = decoder.decode(words.view(np.uint8))
    assert decoder.outside == 3 < OUTSIDE_REFUSED_MIN and len(got.t_ns) == inside.sum()
    np.testing.assert_array_equal(got.x, expected["x"][inside])
    assert make(W + 64, H).decode(words.view(np.uint8)).x.max() >= W  # on a wider sensor they are kept
    # a sensor much smaller than the events': refused, naming the first outside event's word
    with pytest.raises(WordError, match=r"byte \d+: \d+ of \d+ events fall outside the 320x240 sensor"):
        make(320, 240).decode(words.view(np.uint8))


@pytest.mark.parametrize("name", FORMATS)
def test_damaged_words_are_a_value_error_naming_the_byte(name):
    """Seeded random words and cut packets: decoded (random words may be valid) or a ValueError
    naming a byte inside the packet, never a crash; a word of an undefined type is named."""
    make, encode, _ = FORMATS[name]
    rng = np.random.default_rng(11)
    words, _, _ = encode(random_stream(500, W, H, seed=6, t0_us=1000, span_us=20_000), None)
    refused = 0
    for trial in range(300):
        data = words.view(np.uint8).copy()
        if trial % 3 == 0:
            data = rng.integers(0, 256, rng.integers(1, 4000), dtype=np.uint8)  # noise, any length
        elif trial % 3 == 1:
            data[rng.integers(0, len(data), 5)] ^= rng.integers(1, 256, 5, dtype=np.uint8)  # bytes flipped
        else:
            data = data[: rng.integers(1, len(data))]  # a cut packet
        try:
            make(W, H).decode(data)
        except WordError as exc:
            assert 0 <= exc.offset < len(data) and str(exc).startswith(f"byte {exc.offset}: ")
            refused += 1
    assert refused > 100
    bad = words.copy()
    bad[len(bad) // 2] = {"evt3": 0x9ABC, "evt2": 0x9000_0001, "evt21": 0x9 << 60, "evt21-legacy": 0x9 << 28}[name]
    with pytest.raises(
        WordError, match=rf"^byte {len(bad) // 2 * bad.itemsize}: word 0x[0-9a-f]+ is of no EVT .* type \(type 9\)"
    ):
        make(W, H).decode(bad.view(np.uint8))


def test_real_evt3_packets_give_event_camera_pys_sums():
    """event_camera_py's tests/test_1.py states, for this bag: 218291 OFF and 125183 ON events,
    2078 trigger edges of each kind, and the sum of every event and trigger time [us]
    2885601049874. Its counter calls edge 0 "rising" and never checks the other count (it
    compares the rising count twice): the bag holds 2078 edges 0 and 2079 edges 1. The first
    sensor time it states (7139840 us) is that of the first TIME_HIGH and TIME_LOW, before the
    first event."""
    packets = event_camera_py_packets()
    assert {m.encoding for m in packets} == {"evt3"} and {(m.width, m.height) for m in packets} == {(640, 480)}
    decoder = Evt3Decoder(640, 480)
    off = on = edges0 = edges1 = total_us = 0
    first = last = None
    for m in packets:
        d = decoder.decode(np.asarray(m.events, np.uint8), m.time_base)
        off, on = off + int(np.sum(d.p == 0)), on + int(np.sum(d.p == 1))
        edges0, edges1 = edges0 + int(np.sum(d.trigger_edge == 0)), edges1 + int(np.sum(d.trigger_edge == 1))
        total_us += int(np.sum(d.t_ns // 1000)) + int(np.sum(d.trigger_t_ns // 1000))
        assert np.all(d.t_ns % 1000 == 0) and np.all(np.diff(d.t_ns) >= 0)
        if len(d.t_ns):
            assert last is None or d.t_ns[0] >= last
            first = d.t_ns[0] if first is None else first
            last = d.t_ns[-1]
    assert (off, on, edges0, edges1, total_us) == (218291, 125183, 2078, 2079, 2885601049874)
    assert decoder.outside == 0 and decoder.skipped == 0
    words = np.asarray(packets[0].events, np.uint8).view("<u2")
    high = int(np.flatnonzero(words >> 12 == 0x8)[0])
    low = high + int(np.flatnonzero(words[high:] >> 12 == 0x6)[0])
    assert (int(words[high]) & 0xFFF) << 12 | int(words[low]) & 0xFFF == 7139840 <= first // 1000
