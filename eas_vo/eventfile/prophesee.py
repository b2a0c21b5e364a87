"""Prophesee's event encodings: EVT 3.0 (16-bit words), EVT 2.0 (32-bit) and EVT 2.1 (64-bit),
little-endian, as Prophesee's sensors write them (`.raw` files, `event_camera_msgs` packets).

Word layouts: Prophesee's public format pages (docs.prophesee.ai, "EVT 3.0 Format", "EVT 2.0
Format", "EVT 2.1 Format"). Decoding rules where the pages leave a choice follow the reference
decoders, read (not copied) at:
- event_camera_codecs (github.com/ros-event-camera/event_camera_codecs,
  include/event_camera_codecs/evt3_decoder.h) for EVT 3.0: no event or trigger before the first
  TIME_HIGH followed by a TIME_LOW; a TIME_HIGH going back by more than 10 of its units is a
  roll-over of the 24-bit time (+2^24 us), a smaller step back a sensor glitch (the time goes
  back with it); TIME_LOW is kept across a TIME_HIGH; VECT_12 / VECT_8 advance the vector base
  by 12 / 8; EXT_TRIGGER: edge bit 0, channel bits 8-11. Unlike codecs (which reads only time
  words until then, leaving row 0), an ADDR_Y or VECT_BASE_X before the first time holds for the
  events after it (expelliarmus' files put ADDR_Y first), and no event is placed before the
  first ADDR_Y (skipped and counted).
- OpenEB (github.com/prophesee-ai/openeb, hal/cpp/include/metavision/hal/decoders/evt2/ and
  evt21/) for EVT 2.0 and 2.1: nothing is decoded before the first TIME_HIGH; a TIME_HIGH going
  back by at least its whole range less 10 ms is a roll-over of the 34-bit time (+2^34 us);
  EVT 2.1 "legacy" endianness (IMX636 on older boards: the word's two 32-bit halves swapped).

Every decoder skips OTHERS and CONTINUED words (monitoring data; EVT 2.0's IMU words too) and
refuses a word of no type its format defines (a ValueError naming its byte offset): damaged
input, or bytes of another format. Events outside the sensor are dropped, as both references
drop them, and counted (`PropheseeDecoder.outside`); a packet where more than OUTSIDE_REFUSED
of the events fall outside (at least OUTSIDE_REFUSED_MIN of them) is refused: the sensor size
given is wrong, or the bytes are not of this format.

Times: the sensor's microseconds, scaled to ns (x 1000) in Decoded.t_ns. The words carry the
sensor's whole clock: `time_base_ns` is unused (event_camera_msgs sets it 0 for evt3).
Work is bounded by the input: at most 32 events a word, each word read once.
"""

from __future__ import annotations

from typing import ClassVar

import numba
import numpy as np

from eas_vo.eventfile.packets import Decoded, PacketDecoder

#: A decode call refuses its packet when more than this fraction of the events fall outside the sensor...
OUTSIDE_REFUSED = 0.1
#: ...and at least this many do (a few stray events are dropped and counted only).
OUTSIDE_REFUSED_MIN = 16
#: Events decoded per kernel call (the output buffers' size; a packet may take several calls).
CHUNK_EVENTS = 1 << 18

# The decoder state carried from packet to packet (an int64 array, read and written by the kernels).
_HIGH = 0  # the time high [us] with its roll-overs: t = high | low
_LOW = 1  # EVT 3.0's TIME_LOW [us]
_Y = 2  # EVT 3.0's row (ADDR_Y)
_BASE_X = 3  # EVT 3.0's vector base column (VECT_BASE_X)
_POL = 4  # EVT 3.0's vector polarity
_FLAGS = 5  # _HAVE_HIGH | _TIMED | _HAVE_ROW
_SKIPPED = 6  # events skipped before the first full time (EVT 3.0: or the first row), so far
_STATE = 7
_HAVE_HIGH, _TIMED, _HAVE_ROW = 1, 2, 4
_READY = _TIMED | _HAVE_ROW

# What a kernel call reports (an int64 array).
_NEXT = 0  # the word to resume from (the input's length when done)
_EVENTS = 1
_TRIGGERS = 2
_OUTSIDE = 3  # events dropped outside the sensor
_FIRST_OUTSIDE = 4  # the word of the first of them, its x and y
_FIRST_OUTSIDE_X = 5
_FIRST_OUTSIDE_Y = 6
_BAD = 7  # the first word of no type of the format, or -1
_REPORT = 8


@numba.njit(cache=True, nogil=True, inline="always")
def _event(out_t, out_x, out_y, out_p, report, word, t, x, y, p, width, height):
    """Append one event (t [us], x, y [px], p) at report[_EVENTS], or count it as outside the sensor."""
    if x < width and y < height:
        n = report[_EVENTS]
        out_t[n], out_x[n], out_y[n], out_p[n] = t, x, y, p
        report[_EVENTS] = n + 1
        return
    if report[_OUTSIDE] == 0:
        report[_FIRST_OUTSIDE], report[_FIRST_OUTSIDE_X], report[_FIRST_OUTSIDE_Y] = word, x, y
    report[_OUTSIDE] += 1


@numba.njit(cache=True, nogil=True, inline="always")
def _trigger(trig_t, trig_edge, trig_id, report, t, edge, channel):
    m = report[_TRIGGERS]
    trig_t[m], trig_edge[m], trig_id[m] = t, edge, channel
    report[_TRIGGERS] = m + 1


@numba.njit(cache=True, nogil=True)
def decode_evt3(words, start, state, width, height, out_t, out_x, out_y, out_p, trig_t, trig_edge, trig_id, report):
    """EVT 3.0 words[start:] (uint16) into the outputs, until the end, a bad word, or outputs
    too full for another word (12 events, 1 trigger). See the module's rules; `report` as _REPORT."""
    high, low, row, base_x, pol, flags = (
        state[_HIGH],
        state[_LOW],
        state[_Y],
        state[_BASE_X],
        state[_POL],
        state[_FLAGS],
    )
    room_events, room_triggers = len(out_t) - 12, len(trig_t) - 1
    report[_BAD] = -1
    i = start
    while i < len(words) and report[_EVENTS] <= room_events and report[_TRIGGERS] <= room_triggers:
        w = np.int64(words[i])
        code, v = w >> 12, w & 0xFFF
        if code == 0x8:  # TIME_HIGH
            last = (high >> 12) & 0xFFF
            if v < last and last - v > 10:
                high += 1 << 24
            high = (high & ~np.int64(0xFFFFFF)) | (v << 12)
            flags |= _HAVE_HIGH
        elif code == 0x6:  # TIME_LOW
            low = v
            if flags & _HAVE_HIGH:
                flags |= _TIMED
        elif code == 0x7 or code == 0xE or code == 0xF:  # CONTINUED_4, OTHERS, CONTINUED_12
            pass
        elif code == 0x0:  # ADDR_Y
            row = v & 0x7FF
            flags |= _HAVE_ROW
        elif code == 0x3:  # VECT_BASE_X
            base_x, pol = v & 0x7FF, (v >> 11) & 1
        elif code == 0x2 or code == 0x4 or code == 0x5:  # ADDR_X, VECT_12, VECT_8
            bits = 1 if code == 0x2 else 12 if code == 0x4 else 8
            if flags & _READY != _READY:  # no time or no row yet: skipped, counted
                for k in range(bits):
                    state[_SKIPPED] += 1 if code == 0x2 else (v >> k) & 1
            elif code == 0x2:
                _event(out_t, out_x, out_y, out_p, report, i, high | low, v & 0x7FF, row, (v >> 11) & 1, width, height)
            else:
                for k in range(bits):
                    if (v >> k) & 1:
                        _event(out_t, out_x, out_y, out_p, report, i, high | low, base_x + k, row, pol, width, height)
            if code != 0x2:
                base_x += bits
        elif code == 0xA:  # EXT_TRIGGER
            if flags & _TIMED:
                _trigger(trig_t, trig_edge, trig_id, report, high | low, v & 1, (v >> 8) & 0xF)
        else:
            report[_BAD] = i
            break
        i += 1
    state[_HIGH], state[_LOW], state[_Y], state[_BASE_X], state[_POL], state[_FLAGS] = (
        high,
        low,
        row,
        base_x,
        pol,
        flags,
    )
    report[_NEXT] = i


#: EVT 2.x: a TIME_HIGH (28 bits of 64 us) going back by at least this many units is a roll-over
#: (OpenEB: the whole range less 10 ms).
_EVT2_LOOP_UNITS = (1 << 28) - 1 - 10_000 // 64


@numba.njit(cache=True, nogil=True)
def decode_evt2(
    words, start, state, width, height, out_t, out_x, out_y, out_p, trig_t, trig_edge, trig_id, report, legacy
):
    """EVT 2.0 words[start:] (uint32) or EVT 2.1 words (uint64; `legacy`: their 32-bit halves
    swapped), as decode_evt3 (room for 32 events, 1 trigger a word). An EVT 2.1 word is an EVT
    2.0 word (type, 6 time bits, x, y; TIME_HIGH and EXT_TRIGGER alike) in its upper half and
    the valid bits of 32 pixels from x in its lower half."""
    vectors = words.itemsize == 8
    pixels = 32 if vectors else 1
    room_events, room_triggers = len(out_t) - 32, len(trig_t) - 1
    report[_BAD] = -1
    i = start
    while i < len(words) and report[_EVENTS] <= room_events and report[_TRIGGERS] <= room_triggers:
        u = np.uint64(words[i])
        if legacy:
            u = (u << np.uint64(32)) | (u >> np.uint64(32))
        w = np.int64(u >> np.uint64(32)) if vectors else np.int64(u)
        valid = np.int64(u & np.uint64(0xFFFFFFFF)) if vectors else np.int64(1)
        code = w >> 28
        if code == 0x8:  # EVT_TIME_HIGH: 28 bits of 64 us
            high, v = state[_HIGH], w & 0xFFFFFFF
            last = (high >> 6) & 0xFFFFFFF
            if v < last and last - v >= _EVT2_LOOP_UNITS:
                high += np.int64(1) << 34
            state[_HIGH] = (high & ~np.int64((1 << 34) - 1)) | (v << 6)
            state[_FLAGS] |= _HAVE_HIGH | _TIMED
        elif code == 0xE or code == 0xF or (code == 0xD and not vectors):  # OTHERS, CONTINUED, EVT 2.0's IMU_EVT
            pass
        elif code != 0x0 and code != 0x1 and code != 0xA:
            report[_BAD] = i
            break
        elif not state[_FLAGS] & _TIMED:
            if code != 0xA:
                for k in range(pixels):
                    state[_SKIPPED] += (valid >> k) & 1
        elif code == 0xA:  # EXT_TRIGGER
            _trigger(trig_t, trig_edge, trig_id, report, state[_HIGH] | ((w >> 22) & 0x3F), w & 1, (w >> 8) & 0x1F)
        else:  # CD_OFF / EVT_NEG, CD_ON / EVT_POS
            t, x0, y = state[_HIGH] | ((w >> 22) & 0x3F), (w >> 11) & 0x7FF, w & 0x7FF
            for k in range(pixels):
                if (valid >> k) & 1:
                    _event(out_t, out_x, out_y, out_p, report, i, t, x0 + k, y, code, width, height)
        i += 1
    report[_NEXT] = i


class WordError(ValueError):
    """A word of no type of the format (or a length that is not whole words) at `offset` [bytes]
    from the start of the data decoded."""

    def __init__(self, offset: int, reason: str):
        super().__init__(f"byte {offset}: {reason}")
        self.offset, self.reason = offset, reason


class PropheseeDecoder(PacketDecoder):
    """A Prophesee EVT decoder (one per stream, its packets in order): `decode` as PacketDecoder.

    Attributes:
        outside: events dropped outside the sensor so far.
        skipped: events skipped before the stream's first full time (EVT 3.0: or row) so far.
    """

    #: The format's name, for messages.
    title: ClassVar[str]
    #: Bytes a word.
    word_bytes: ClassVar[int]
    #: The compiled word loop (decode_evt3's arguments, then `_options()`).
    kernel: ClassVar

    def __init__(self, width: int, height: int):
        super().__init__(width, height)
        self.state = np.zeros(_STATE, np.int64)
        self.outside = 0

    @property
    def skipped(self) -> int:
        return int(self.state[_SKIPPED])

    def _options(self) -> tuple:
        """The kernel's arguments after decode_evt3's."""
        return ()

    def decode(self, data, time_base_ns: int = 0) -> Decoded:
        """One packet's bytes (uint8 array or bytes-like) -> its events and triggers."""
        data = np.frombuffer(data, np.uint8) if not isinstance(data, np.ndarray) else data.reshape(-1).view(np.uint8)
        if len(data) % self.word_bytes:
            whole = len(data) - len(data) % self.word_bytes
            raise WordError(
                whole,
                f"{len(data) - whole} byte(s) after the last whole {8 * self.word_bytes}-bit "
                f"{self.title} word (a cut packet or file?)",
            )
        words = data.view(f"<u{self.word_bytes}").astype(f"=u{self.word_bytes}", copy=False)
        size = min(CHUNK_EVENTS, 32 * len(words) + 32)
        parts, report, start = [], np.zeros(_REPORT, np.int64), 0
        first_outside = None
        outside = total = 0
        while True:
            out = (
                np.empty(size, np.int64),
                np.empty(size, np.uint16),
                np.empty(size, np.uint16),
                np.empty(size, np.uint8),
                np.empty(size, np.int64),
                np.empty(size, np.uint8),
                np.empty(size, np.uint8),
            )
            report[:] = 0
            self.kernel(words, start, self.state, self.width, self.height, *out, report, *self._options())
            n, m = int(report[_EVENTS]), int(report[_TRIGGERS])
            parts.append([a[:k] for a, k in zip(out, (n, n, n, n, m, m, m))])
            if report[_OUTSIDE] and first_outside is None:
                first_outside = tuple(int(v) for v in report[_FIRST_OUTSIDE : _FIRST_OUTSIDE_Y + 1])
            outside += int(report[_OUTSIDE])
            total += n
            if report[_BAD] >= 0:
                bad = int(report[_BAD])
                raise WordError(
                    bad * self.word_bytes,
                    f"word 0x{int(words[bad]):0{2 * self.word_bytes}x} is of no "
                    f"{self.title} type (type {self._type_of(int(words[bad]))})",
                )
            start = int(report[_NEXT])
            if start >= len(words):
                break
        if outside > OUTSIDE_REFUSED * (total + outside) and outside >= OUTSIDE_REFUSED_MIN:
            word, x, y = first_outside
            raise WordError(
                word * self.word_bytes,
                f"{outside} of {total + outside} events fall outside the "
                f"{self.width}x{self.height} sensor (the first at x={x}, y={y}): the "
                f"sensor size is wrong, or these are not {self.title} words",
            )
        self.outside += outside
        columns = [np.concatenate(c) if len(parts) > 1 else c[0] for c in zip(*parts)]
        t_us, x, y, p, trig_us, edge, channel = columns
        return Decoded(
            t_ns=t_us * 1000, x=x, y=y, p=p, trigger_t_ns=trig_us * 1000, trigger_edge=edge, trigger_id=channel
        )

    def _type_of(self, word: int) -> int:
        return word >> (8 * self.word_bytes - 4)


class Evt3Decoder(PropheseeDecoder):
    """EVT 3.0: 16-bit words, vectors of 12 and 8 pixels, a 24-bit microsecond time that rolls over."""

    encoding = "evt3"
    title = "EVT 3.0"
    word_bytes = 2
    kernel = staticmethod(decode_evt3)


class Evt2Decoder(PropheseeDecoder):
    """EVT 2.0: 32-bit words, one event each."""

    encoding = "evt2"
    title = "EVT 2.0"
    word_bytes = 4
    kernel = staticmethod(decode_evt2)

    def _options(self) -> tuple:
        return (False,)


class Evt21Decoder(PropheseeDecoder):
    """EVT 2.1: 64-bit words, vectors of 32 pixels; `legacy`: the 32-bit halves of each word
    swapped (OpenEB's `endianness=legacy`: IMX636 on older boards)."""

    encoding = "evt21"
    title = "EVT 2.1"
    word_bytes = 8
    kernel = staticmethod(decode_evt2)

    def __init__(self, width: int, height: int, legacy: bool = False):
        super().__init__(width, height)
        self.legacy = legacy

    def _options(self) -> tuple:
        return (self.legacy,)

    def _type_of(self, word: int) -> int:
        return (word & 0xFFFFFFFF) >> 28 if self.legacy else word >> 60


#: The decoder of each format name (a `.raw` header's `format` name and event_camera_msgs' encoding).
DECODERS: dict[str, type[PropheseeDecoder]] = {"EVT3": Evt3Decoder, "EVT2": Evt2Decoder, "EVT21": Evt21Decoder}
