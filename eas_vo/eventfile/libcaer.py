"""iniVation's event encodings in `event_camera_msgs/EventPacket` (ros-event-camera's
`libcaer_driver`, DAVIS and DVXplorer): `libcaer` and `libcaer_cmp`, decoded by compiled loops.

Both carry polarity events only (no trigger words). The message's `time_base` [ns] is libcaer's
sensor time, aligned with host time when the driver started:

- `libcaer`: libcaer's polarity events as they come from the device, 8 bytes each, little-endian
  (libcaer `include/libcaer/events/polarity.h`): a 32-bit data word (bit 0 the valid mark, bit 1
  the polarity, bits 2-16 y, bits 17-31 x) and a 32-bit timestamp [us], the low 31 bits of the
  sensor time. `time_base` is the host start time + the sensor time's bits from 31 up, so an
  event is at time_base + 1000 * timestamp, plus 2^31 us for each roll-over of the 31 bits
  within the packet (event_camera_codecs `libcaer_decoder.h`, `loopOverTime`). Events whose
  valid mark is clear are not events (libcaer's iterators skip them); their times still count.
- `libcaer_cmp`: 16-bit little-endian words, the code in the top 4 bits (event_camera_codecs
  `libcaer_cmp_types.h`, `libcaer_cmp_decoder.h`; written by libcaer_driver
  `src/message_converter.cpp`): 0 TIME_HIGH (bits 12-23 of dt), 1 TIME_LOW (bits 0-11),
  2 ADDR_X (x, 11 bits), 3 ADDR_Y (one event at y, bit 11 the polarity), 4 VECT_BASE_Y (a base y
  and polarity), 5 VECT_8 (bit i set: an event at base y + i; the base then moves up by 8).
  dt [us] starts at 0 in each packet (the packet's first event is at `time_base`), so an event is
  at time_base + 1000 * dt. The x address, base y and polarity carry on to the next packet.

Damaged bytes are a ValueError naming the byte offset in the packet: a word no writer makes, an
event before its address, an event outside the sensor, a time that steps back or jumps by 2^30 us
(18 min) or more between consecutive events of one packet. The loops are linear in the bytes.
"""

from __future__ import annotations

import numba
import numpy as np

from eas_vo.eventfile.packets import Decoded, PacketDecoder

INT64_MAX = np.iinfo(np.int64).max
#: One roll-over of libcaer's 31-bit microsecond timestamp [ns].
ROLL_OVER_NS = (1 << 31) * 1000
#: A step between consecutive events of one packet this long [us] or longer is damage.
MAX_STEP_US = 1 << 30
#: libcaer_cmp's dt is 24 bits [us]: its largest offset from time_base [ns].
CMP_SPAN_NS = (1 << 24) * 1000

# What a kernel found wrong (its second return value; 0 = nothing).
OK, NEGATIVE_TIME, TIME_STEP, OUTSIDE, TIME_RANGE, UNKNOWN_CODE, NO_X, NO_BASE_Y, TIME_BACK = range(9)
CMP_CODES = ("TIME_HIGH", "TIME_LOW", "ADDR_X", "ADDR_Y", "VECT_BASE_Y", "VECT_8", "VECT_12")
#: libcaer_cmp's carried state: x address, base y, vector polarity, x seen, base y seen.
CMP_STATE = 5


@numba.njit(cache=True, nogil=True, inline="always")
def _le(data, o, nbytes):
    """The little-endian unsigned integer of `nbytes` bytes at data[o:] (as int64)."""
    v = np.int64(0)
    for b in range(nbytes):
        v |= np.int64(data[o + b]) << (8 * b)
    return v


@numba.njit(cache=True, nogil=True, inline="always")
def _emit(t, x, y, p, n, t_ns, ex, ey, pol):
    """Write event n into the columns."""
    t[n] = t_ns
    x[n] = ex
    y[n] = ey
    p[n] = pol


@numba.njit(cache=True, nogil=True)
def libcaer_kernel(data, time_base_ns, width, height, t, x, y, p):
    """Decode `libcaer` bytes (a multiple of 8) into t [ns], x, y, p (each of len(data) // 8).

    Returns (events written, problem code, byte offset, two details); the time_base must leave
    room below INT64_MAX for one timestamp (checked by the caller)."""
    n = 0
    high_ns = np.int64(time_base_ns)
    last_us = np.int64(-1)
    for o in range(0, len(data) - 7, 8):
        d = _le(data, o, 4)
        ts = _le(data, o + 4, 4)
        if ts >= 1 << 31:
            return n, NEGATIVE_TIME, o + 4, ts, 0
        if last_us >= 0:
            step = ts - last_us
            rolled = step < 0
            if rolled:
                step += 1 << 31
            if step >= MAX_STEP_US:
                return n, TIME_STEP, o + 4, last_us, ts
            if rolled:
                if high_ns > INT64_MAX - 2 * ROLL_OVER_NS:
                    return n, TIME_RANGE, o + 4, high_ns, 0
                high_ns += ROLL_OVER_NS
        last_us = ts
        if d & 1 == 0:
            continue
        ex = (d >> 17) & 0x7FFF
        ey = (d >> 2) & 0x7FFF
        if ex >= width or ey >= height:
            return n, OUTSIDE, o, ex, ey
        _emit(t, x, y, p, n, high_ns + 1000 * ts, ex, ey, (d >> 1) & 1)
        n += 1
    return n, OK, -1, 0, 0


@numba.njit(cache=True, nogil=True)
def libcaer_cmp_count(data):
    """The number of events the `libcaer_cmp` words of `data` (an even length) hold at most."""
    n = 0
    for o in range(0, len(data) - 1, 2):
        code = data[o + 1] >> 4
        if code == 3:
            n += 1
        elif code == 5:
            m = data[o]
            while m:
                n += m & 1
                m >>= 1
    return n


@numba.njit(cache=True, nogil=True)
def libcaer_cmp_kernel(data, time_base_ns, width, height, state, t, x, y, p):
    """Decode `libcaer_cmp` words (an even length) into t [ns], x, y, p (as long as
    libcaer_cmp_count says), updating `state` (CMP_STATE int64s carried between packets).

    Returns (events written, problem code, byte offset, two details)."""
    ex, base_y, vec_pol, has_x, has_base = state[0], state[1], state[2], state[3], state[4]
    high = np.int64(0)
    low = np.int64(0)
    last_us = np.int64(-1)
    n = 0
    for o in range(0, len(data) - 1, 2):
        w = _le(data, o, 2)
        code = w >> 12
        dt_us = high | low
        if code == 0:
            high = (w & 0xFFF) << 12
        elif code == 1:
            low = w & 0xFFF
        elif code == 2:
            ex = w & 0x7FF
            has_x = 1
        elif code == 3 or code == 5:
            if not has_x:
                return n, NO_X, o, code, 0
            if dt_us < last_us:
                return n, TIME_BACK, o, last_us, dt_us
            last_us = dt_us
            if code == 3:
                ey = w & 0x7FF
                if ex >= width or ey >= height:
                    return n, OUTSIDE, o, ex, ey
                _emit(t, x, y, p, n, time_base_ns + 1000 * dt_us, ex, ey, (w >> 11) & 1)
                n += 1
            else:
                if not has_base:
                    return n, NO_BASE_Y, o, 0, 0
                for b in range(8):
                    if (w >> b) & 1:
                        if ex >= width or base_y + b >= height:
                            return n, OUTSIDE, o, ex, base_y + b
                        _emit(t, x, y, p, n, time_base_ns + 1000 * dt_us, ex, base_y + b, vec_pol)
                        n += 1
                base_y += 8
        elif code == 4:
            base_y = w & 0x7FF
            vec_pol = (w >> 11) & 1
            has_base = 1
        else:
            return n, UNKNOWN_CODE, o, code, 0
    state[0], state[1], state[2], state[3], state[4] = ex, base_y, vec_pol, has_x, has_base
    return n, OK, -1, 0, 0


#: What each problem code says; {a}, {b}: the kernel's details, {code}: a's word name.
PROBLEMS = {
    NEGATIVE_TIME: "timestamp {a:#x} has bit 31 set (libcaer's are 31-bit microseconds)",
    TIME_STEP: "time jumps from {a} us to {b} us (a step of 2^30 us or more, roll-over counted)",
    OUTSIDE: "event at x={a}, y={b} outside the {width}x{height} sensor",
    TIME_RANGE: "event time beyond the int64 nanosecond range",
    UNKNOWN_CODE: "word code {a} ({code})",
    NO_X: "{code} event before any ADDR_X word",
    NO_BASE_Y: "VECT_8 event before any VECT_BASE_Y word",
    TIME_BACK: "event time steps back from {a} us to {b} us after the time base",
}


def _problem(encoding: str, code: int, offset: int, a: int, b: int, width: int, height: int) -> str:
    """One line naming the byte and what is wrong there."""
    name = CMP_CODES[a] if 0 <= a < len(CMP_CODES) else "no libcaer_cmp word has it"
    if code == UNKNOWN_CODE and a < len(CMP_CODES):
        name += ", which libcaer_driver does not write"
    what = PROBLEMS[code].format(a=a, b=b, width=width, height=height, code=name)
    return f"{encoding} packet, byte {offset}: {what}"


def _packet(data, word_bytes: int, encoding: str) -> np.ndarray:
    """The packet's bytes as a contiguous uint8 array, whole words only (else ValueError)."""
    data = np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)
    if len(data) % word_bytes:
        cut = len(data) - len(data) % word_bytes
        raise ValueError(
            f"{encoding} packet, byte {cut}: cut inside a word ({len(data)} bytes, not a multiple of {word_bytes})"
        )
    return data


def _time_base(time_base_ns, span_ns: int, encoding: str) -> np.int64:
    """The message's time_base [ns], checked to leave room for the encoding's span after it."""
    if not 0 <= int(time_base_ns) <= INT64_MAX - span_ns:
        raise ValueError(f"{encoding} packet: time_base {int(time_base_ns)} ns is outside 0..{INT64_MAX - span_ns}")
    return np.int64(time_base_ns)


def _columns(n: int) -> tuple[np.ndarray, ...]:
    return np.empty(n, np.int64), np.empty(n, np.uint16), np.empty(n, np.uint16), np.empty(n, np.uint8)


def _decoded(n: int, t, x, y, p) -> Decoded:
    """The first n events; no triggers (neither encoding has them)."""
    return Decoded(t[:n], x[:n], y[:n], p[:n], np.empty(0, np.int64), np.empty(0, np.uint8), np.empty(0, np.uint8))


class LibcaerDecoder(PacketDecoder):
    """`libcaer`: libcaer's uncompressed polarity events (8 bytes each)."""

    encoding = "libcaer"
    host_clock = True

    def decode(self, data: np.ndarray, time_base_ns: int) -> Decoded:
        data = _packet(data, 8, self.encoding)
        base = _time_base(time_base_ns, ROLL_OVER_NS, self.encoding)
        cols = _columns(len(data) // 8)
        n, code, offset, a, b = libcaer_kernel(data, base, self.width, self.height, *cols)
        if code != OK:
            raise ValueError(_problem(self.encoding, code, offset, a, b, self.width, self.height))
        return _decoded(n, *cols)


class LibcaerCmpDecoder(PacketDecoder):
    """`libcaer_cmp`: libcaer_driver's compressed polarity events (16-bit words); keeps the x
    address, base y and polarity from one packet to the next (a damaged packet leaves them)."""

    encoding = "libcaer_cmp"
    host_clock = True

    def __init__(self, width: int, height: int):
        super().__init__(width, height)
        self.state = np.zeros(CMP_STATE, np.int64)

    def decode(self, data: np.ndarray, time_base_ns: int) -> Decoded:
        data = _packet(data, 2, self.encoding)
        base = _time_base(time_base_ns, CMP_SPAN_NS, self.encoding)
        cols = _columns(libcaer_cmp_count(data))
        state = self.state.copy()
        n, code, offset, a, b = libcaer_cmp_kernel(data, base, self.width, self.height, state, *cols)
        if code != OK:
            raise ValueError(_problem(self.encoding, code, offset, a, b, self.width, self.height))
        self.state = state
        return _decoded(n, *cols)
