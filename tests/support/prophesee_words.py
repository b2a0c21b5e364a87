"""A test encoder of Prophesee's EVT 3.0, 2.0 and 2.1 words (the layouts of Prophesee's format
pages), written independently of the decoder it checks, and `.raw` files with a header.

Each encoder takes events (t [us], x, y, p, sorted by t) and trigger edges (t [us], edge, id)
and returns the words with the events in the order the words hold them (a decoder must return
exactly these) and the triggers likewise. Monitoring words (OTHERS + CONTINUED) are put in
every `others_every` time steps: a decoder skips them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers import SHARED_DATA, require

#: event_camera_py's ROS 2 test bag: EVT 3.0 packets of a Prophesee camera (event_camera_msgs).
EVENT_CAMERA_PY = SHARED_DATA / "real_files" / "event_camera_py" / "test_events_1"

EVENT = np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
TRIGGER = np.dtype([("t", "<i8"), ("edge", "u1"), ("id", "u1")])


def random_stream(
    n: int, width: int, height: int, seed: int = 0, t0_us: int = 0, span_us: int = 200_000, runs: bool = True
) -> np.ndarray:
    """n events over [t0, t0 + span) us, sorted by time; with `runs`, many in rows of neighbours
    at one time and polarity (what EVT 3.0 and 2.1 vectorise)."""
    rng = np.random.default_rng(seed)
    ev = np.empty(n, EVENT)
    ev["t"] = np.sort(t0_us + rng.integers(0, span_us, n))
    ev["x"], ev["y"], ev["p"] = rng.integers(0, width, n), rng.integers(0, height, n), rng.integers(0, 2, n)
    if runs:
        k = np.arange(n)
        lead = k - k % 20  # groups of 20 events: one time, row and polarity, x from a base
        span = max(1, min(40, width - 1))
        ev["t"], ev["y"], ev["p"] = ev["t"][lead], ev["y"][lead], ev["p"][lead]
        ev["x"] = np.minimum(ev["x"][lead] + rng.integers(0, span, n), width - 1)
    ev = np.unique(ev)  # one event a pixel, time and polarity; sorted by t, x, y, p
    return ev[np.lexsort((ev["x"], ev["p"], ev["y"], ev["t"]))]


def random_triggers(n: int, t0_us: int, span_us: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tr = np.empty(n, TRIGGER)
    tr["t"] = np.sort(t0_us + rng.integers(0, span_us, n))
    tr["edge"], tr["id"] = np.arange(n) % 2, rng.integers(0, 2, n)
    return tr


def _merged(events, triggers):
    """(time, is_trigger, index) in time order, a trigger before the events of its time."""
    items = [(int(t), 0, i) for i, t in enumerate(triggers["t"])] + [(int(t), 1, i) for i, t in enumerate(events["t"])]
    return sorted(items)


def _groups(events, order):
    """Consecutive runs (from `order`, in it) of events sharing t, y and p."""
    run = []
    for i in order:
        e = events[i]
        if run and (events[run[0]]["t"], events[run[0]]["y"], events[run[0]]["p"]) != (e["t"], e["y"], e["p"]):
            yield run
            run = []
        run.append(i)
    if run:
        yield run


def encode_evt3(events, triggers=None, others_every: int = 7):
    """EVT 3.0 words (uint16) of `events` and `triggers`; (words, events in word order, triggers)."""
    triggers = np.empty(0, TRIGGER) if triggers is None else triggers
    words, out, trig_out = [], [], []
    high = low = row = None  # the time high [4096 us] last written (whole, not wrapped), time low, row
    step = 0

    def time(t):
        nonlocal high, low, step
        if high != t >> 12:
            if high is not None and (t >> 12) - high > 2000:  # a long gap: time highs on the way (as the sensor's)
                words.extend(0x8000 | (f & 0xFFF) for f in range(high + 2000, t >> 12, 2000))
            words.append(0x8000 | ((t >> 12) & 0xFFF))
            high, low = t >> 12, None
        if low != (t & 0xFFF):
            words.append(0x6000 | (t & 0xFFF))
            low = t & 0xFFF
        step += 1
        if others_every and step % others_every == 0:
            words.extend(
                [0xE000 | 0x014, 0xF000 | 0x123, 0xF000 | 0x001, 0x7000 | 0x5]
            )  # OTHERS, CONTINUED_12 x2, CONTINUED_4

    pending = []  # event indices of the current time

    def flush():
        nonlocal row
        for run in _groups(events, pending):
            run = sorted(run, key=lambda i: int(events[i]["x"]))
            e0 = events[run[0]]
            if row != int(e0["y"]):
                words.append(0x0000 | int(e0["y"]))
                row = int(e0["y"])
            xs = [int(events[i]["x"]) for i in run]
            k = 0
            while k < len(run):
                base = xs[k]
                inside = [j for j in range(k, len(run)) if xs[j] < base + 20]
                if len(inside) == 1:
                    words.append(0x2000 | int(e0["p"]) << 11 | base)
                    out.append(run[k])
                    k += 1
                    continue
                words.append(0x3000 | int(e0["p"]) << 11 | base)
                for width, code in ((12, 0x4000), (8, 0x5000)):
                    mask = 0
                    for j in inside:
                        if base <= xs[j] < base + width:
                            mask |= 1 << (xs[j] - base)
                            out.append(run[j])
                    words.append(code | mask)
                    base += width
                k = inside[-1] + 1
        pending.clear()

    current = None
    for t, is_event, i in _merged(events, triggers):
        if t != current:
            flush()
            time(t)
            current = t
        if is_event:
            pending.append(i)
        else:
            flush()
            words.append(0xA000 | int(triggers[i]["id"]) << 8 | int(triggers[i]["edge"]))
            trig_out.append(i)
    flush()
    return np.array(words, np.uint16), events[np.array(out, int)], triggers[np.array(trig_out, int)]


def _evt2x(events, triggers, others_every, word_bits):
    """EVT 2.0 (word_bits 32) or 2.1 (64) words; as encode_evt3."""
    triggers = np.empty(0, TRIGGER) if triggers is None else triggers
    words, out, trig_out = [], [], []
    shift = word_bits - 32  # EVT 2.1: the 2.0 layout in the upper half, the vector mask below
    high = None
    step = 0
    pending = []

    def flush():
        for run in _groups(events, pending):
            e0 = events[run[0]]
            t, y, p = int(e0["t"]), int(e0["y"]), int(e0["p"])
            if word_bits == 32:
                for i in run:
                    words.append((p << 28 | (t & 63) << 22 | int(events[i]["x"]) << 11 | y))
                    out.append(i)
                continue
            bases = sorted({int(events[i]["x"]) & ~31 for i in run})
            for base in bases:
                mask = 0
                for i in run:
                    if int(events[i]["x"]) & ~31 == base:
                        mask |= 1 << (int(events[i]["x"]) - base)
                        out.append(i)
                words.append((p << 28 | (t & 63) << 22 | base << 11 | y) << 32 | mask)
        pending.clear()

    current = None
    for t, is_event, i in _merged(events, triggers):
        if t != current:
            flush()
            if high != t >> 6:
                words.append((0x8 << 28 | ((t >> 6) & 0xFFFFFFF)) << shift)
                high = t >> 6
            step += 1
            if others_every and step % others_every == 0:
                words.extend([(0xE << 28 | 0x14) << shift, (0xF << 28 | 0x5) << shift])
            current = t
        if is_event:
            pending.append(i)
        else:
            flush()
            words.append((0xA << 28 | (t & 63) << 22 | int(triggers[i]["id"]) << 8 | int(triggers[i]["edge"])) << shift)
            trig_out.append(i)
    flush()
    dtype = np.uint32 if word_bits == 32 else np.uint64
    return np.array(words, dtype), events[np.array(out, int)], triggers[np.array(trig_out, int)]


def encode_evt2(events, triggers=None, others_every: int = 7):
    return _evt2x(events, triggers, others_every, 32)


def encode_evt21(events, triggers=None, others_every: int = 7, legacy: bool = False):
    words, out, trig = _evt2x(events, triggers, others_every, 64)
    if legacy:
        words = (words << np.uint64(32)) | (words >> np.uint64(32))
    return words, out, trig


ENCODERS = {"EVT3": encode_evt3, "EVT2": encode_evt2, "EVT21": encode_evt21}


def write_raw(
    path: Path, words: np.ndarray, fmt: str, width: int, height: int, header: list[str] | None = None
) -> Path:
    """A `.raw` file: Metavision's header lines (or `header`), `% end`, then the words little-endian."""
    lines = (
        header
        if header is not None
        else [
            "% camera_integrator_name Prophesee",
            "% date 2024-01-01 00:00:00",
            f"% format {fmt};height={height};width={width}",
            "% end",
        ]
    )
    path.write_bytes(
        "".join(line + "\n" for line in lines).encode() + words.astype(words.dtype.newbyteorder("<")).tobytes()
    )
    return path


def write_dat(path: Path, events: np.ndarray, width: int, height: int, ev_type: int = 12) -> Path:
    """A `.dat` file of CD records (OpenEB's layout): header, type and size bytes, records."""
    header = f"% Data file containing CD events.\n% Version 2\n% Width {width}\n% Height {height}\n".encode()
    records = np.empty((len(events), 2), "<u4")
    records[:, 0] = events["t"]
    records[:, 1] = (
        events["x"].astype(np.uint32) | events["y"].astype(np.uint32) << 14 | events["p"].astype(np.uint32) << 28
    )
    path.write_bytes(header + bytes([ev_type, 8]) + records.tobytes())
    return path


def event_camera_py_packets():
    """The EVT 3.0 EventPacket messages of event_camera_py's test_events_1 bag (ROS 2), in order."""
    from rosbags.rosbag2 import Reader

    from eas_vo.datasets.rosbag2 import bag_typestore

    folder = require(EVENT_CAMERA_PY)
    with Reader(folder) as reader:
        store = bag_typestore(folder, reader.connections)
        return [store.deserialize_cdr(raw, conn.msgtype) for conn, _, raw in reader.messages()]
