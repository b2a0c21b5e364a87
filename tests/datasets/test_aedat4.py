"""The AEDAT4 reader: files written by dv-processing's own MonoCameraWriter (not our code), read
back exactly; units, frame times, validation, the cache, hostile files; and a simulated
sequence giving the same data and the same trajectory as its ECD folder."""

from __future__ import annotations

import json
import re
from datetime import timedelta

import cv2
import numpy as np
import pytest

import helpers
from eas_vo.datasets.aedat4 import Aedat4Config, Aedat4Dataset
from eas_vo.errors import DataError, EasVoError
from eas_vo.registry import open_dataset
from eas_vo.types import ImuSeries

dv = pytest.importorskip("dv_processing", reason="dv-processing (the AEDAT4 reader's library) is not installed")

WIDTH, HEIGHT = 120, 90  # not the DAVIS240's: nothing here may assume 240x180


def write_aedat4(path, *, size=(WIDTH, HEIGHT), **options):
    """helpers.write_aedat4 on this module's sensor by default."""
    helpers.write_aedat4(path, size=size, **options)


def write_calib(folder, width=WIDTH, height=HEIGHT):
    path = folder / "calib.txt"
    path.write_text(f"{0.9 * width} {0.9 * width} {width / 2} {height / 2} -0.1 0.01 0 0 0\n")
    return path


def random_stream(n, seed=0, t0_us=1_700_000_000_000_000):
    """n events in time order (Unix microseconds, as DV records them) on the test sensor."""
    rng = np.random.default_rng(seed)
    t = t0_us + np.sort(rng.integers(0, 2_000_000, n))
    return t, rng.integers(0, WIDTH, n), rng.integers(0, HEIGHT, n), rng.integers(0, 2, n)


def test_can_open_wants_the_suffix_and_the_magic(tmp_path):
    good = tmp_path / "rec.aedat4"
    write_aedat4(good, events=random_stream(10), kind="events")
    text = tmp_path / "notes.aedat4"
    text.write_text("t x y p\n0.1 2 3 1\n")
    renamed = tmp_path / "rec.bin"
    renamed.write_bytes(good.read_bytes())
    assert Aedat4Dataset.can_open(str(good))
    assert not Aedat4Dataset.can_open(str(text)) and not Aedat4Dataset.can_open(str(renamed))
    assert not Aedat4Dataset.can_open(str(tmp_path / "absent.aedat4")) and not Aedat4Dataset.can_open("a\0b.aedat4")
    assert not Aedat4Dataset.can_open(str(tmp_path))
    with pytest.raises(DataError, match=r"notes.aedat4: not an AEDAT4 file"):
        Aedat4Dataset(text, Aedat4Config(calibration=str(write_calib(tmp_path))))
    shouting = tmp_path / "REC.AEDAT4"
    shouting.write_bytes(good.read_bytes())
    assert Aedat4Dataset.can_open(str(shouting))
    assert len(Aedat4Dataset(shouting, Aedat4Config(calibration=str(write_calib(tmp_path)))).events()) == 10


def test_a_missing_calibration_says_what_to_pass(tmp_path):
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=random_stream(10), kind="events")
    ds = Aedat4Dataset(path)  # described by info all the same
    assert ds.camera is None and ds.sensor_size == (WIDTH, HEIGHT) and len(ds.events()) == 10
    with pytest.raises(
        EasVoError,
        match=r"rec.aedat4: an AEDAT4 file holds no lens calibration: give one with "
        r"--set dataset.calibration=FILE",
    ):
        open_dataset(str(path))


def test_events_frames_imu_in_the_projects_units_and_instants(tmp_path):
    """Known answers: events [us] -> s after the clock origin (DV's Unix clock: its first whole
    second, subtracted in integer microseconds, so nothing of the microseconds is lost); a
    frame's time is the middle of its exposure (as the ECD's frames are stamped by the DAVIS ROS
    driver); 1 g -> 9.80665 m/s^2, 180 deg/s -> pi rad/s."""
    events = random_stream(5000)
    t0 = int(events[0][0])
    image = np.random.default_rng(1).integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8)
    frames = [(t0 + 1000, 8000, image), (t0 + 51_000, 3001, image[::-1].copy())]
    imu = [(t0, 0.0, -1.0, 0.5, 180.0, 0.0, -90.0), (t0 + 5000, 1.0, 0.0, 0.0, 0.0, 360.0, 0.0)]
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=events, frames=frames, imu=imu)
    ds = Aedat4Dataset(path, Aedat4Config(calibration=str(write_calib(tmp_path))))

    assert (ds.camera.width, ds.camera.height) == (WIDTH, HEIGHT)
    origin = t0 // 1_000_000 * 1_000_000  # [us]
    assert ds.clock_origin_ns == origin * 1000
    ev = ds.events()
    np.testing.assert_array_equal(np.round(ev["t"] * 1e6).astype(np.int64) + origin, events[0])
    np.testing.assert_array_equal(ev["t"], (events[0] - origin) / 1e6)
    for k, name in ((1, "x"), (2, "y"), (3, "p")):
        np.testing.assert_array_equal(ev[name], events[k])
    np.testing.assert_array_equal(
        ds.frame_times(), [(t0 - origin + 1000 + 4000) / 1e6, (t0 - origin + 51_000 + 1500.5) / 1e6]
    )
    np.testing.assert_array_equal(ds.load_frame(0), image)
    np.testing.assert_array_equal(ds.load_frame(1), image[::-1])
    np.testing.assert_array_equal(ds.imu.t, [(t0 - origin) / 1e6, (t0 - origin + 5000) / 1e6])
    np.testing.assert_allclose(ds.imu.acc, [[0.0, -9.80665, 0.5 * 9.80665], [9.80665, 0.0, 0.0]], rtol=1e-7)
    np.testing.assert_allclose(ds.imu.gyro, [[np.pi, 0.0, -np.pi / 2], [0.0, 2 * np.pi, 0.0]], rtol=1e-7)
    samples = list(ds.samples())
    assert [s.event_index for s in samples] == list(np.searchsorted(ev["t"], ds.frame_times()))


def test_events_are_cached_and_the_cache_is_used(tmp_path):
    path = tmp_path / "rec.aedat4"
    events = random_stream(20_000, seed=2)
    write_aedat4(path, events=events, kind="events")
    config = Aedat4Config(calibration=str(write_calib(tmp_path)))
    first = Aedat4Dataset(path, config).events()
    second = Aedat4Dataset(path, config).events()
    assert isinstance(second, np.memmap)
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(second["x"], events[1])


@pytest.mark.parametrize("compression", ["NONE", "LZ4", "LZ4_HIGH", "ZSTD", "ZSTD_HIGH"])
@pytest.mark.parametrize("group_bytes", [1, 1 << 20])
def test_every_compression_reads_what_dv_processing_reads(tmp_path, monkeypatch, compression, group_bytes):
    """The event packets, decoded by eas-vo (not dv-processing), against dv-processing's own
    batch reading of the same file: every event, in order, many packets, each compression; one
    packet per task (the tasks' buffers reused around their ring) or all in one; decompressed
    into a buffer too small for a packet (it grows) the same as into memory of its own."""
    from eas_vo.datasets import aedat4
    from eas_vo.datasets.aedat4_packets import Aedat4File, Scratch

    monkeypatch.setattr(aedat4, "GROUP_BYTES", group_bytes)
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=random_stream(25_000, seed=7), kind="events", compression=compression, packet=1000)
    ds = Aedat4Dataset(path, Aedat4Config(calibration=str(write_calib(tmp_path))))
    ours = ds.events()
    packets, scratch = Aedat4File(path), Scratch(64)
    for k in range(len(packets)):
        assert packets.event_records(k, scratch).tobytes() == packets.event_records(k).tobytes()
    assert len(scratch.buffer) >= 16_000 if compression != "NONE" else len(scratch.buffer) == 64
    recording, batches = dv.io.MonoCameraRecording(str(path)), []
    while (batch := recording.getNextEventBatch()) is not None:
        batches.append(batch.numpy())
    theirs = np.concatenate(batches)
    assert len(batches) == 25 and len(ours) == len(theirs) == 25_000
    np.testing.assert_array_equal(ours["t"], (theirs["timestamp"] - ds.clock_origin_ns // 1000) / 1e6)
    np.testing.assert_array_equal(ours["x"], theirs["x"])
    np.testing.assert_array_equal(ours["y"], theirs["y"])
    np.testing.assert_array_equal(ours["p"], theirs["polarity"] != 0)


@pytest.mark.parametrize("compression", ["NONE", "LZ4", "ZSTD"])
def test_frames_and_imu_read_what_dv_processing_reads(tmp_path, compression):
    """Frames (grey, BGR, BGRA) and IMU readings decoded by eas-vo against dv-processing's own
    reading of the same file: the same times, exposures, pixels and values."""
    rng = np.random.default_rng(5)
    t0 = 1_700_000_000_000_000
    grey = rng.integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8)
    images = [
        grey,
        rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8),
        rng.integers(0, 256, (HEIGHT, WIDTH, 4), dtype=np.uint8),
    ]
    frames = [(t0 + 30_000 * k, 1000 + 7 * k, image) for k, image in enumerate(images)]
    imu = [(t0 + 1000 * k, *rng.normal(size=6)) for k in range(50)]
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=random_stream(100), frames=frames, imu=imu, compression=compression)
    ours = Aedat4Dataset(path, Aedat4Config(calibration=str(write_calib(tmp_path))))
    recording, theirs, readings = dv.io.MonoCameraRecording(str(path)), [], []
    while (frame := recording.getNextFrame()) is not None:
        theirs.append(frame)
    while (batch := recording.getNextImuBatch()) is not None:
        readings.extend(batch)
    assert len(theirs) == len(ours.frame_times()) == 3
    for k, frame in enumerate(theirs):
        middle_us = frame.timestamp + frame.exposure / timedelta(microseconds=1) / 2
        assert ours.frame_times()[k] == (middle_us - ours.clock_origin_ns // 1000) / 1e6
        conversion = {2: None, 3: cv2.COLOR_BGR2GRAY, 4: cv2.COLOR_BGRA2GRAY}[
            frame.image.ndim if frame.image.ndim == 2 else frame.image.shape[2]
        ]
        expected = frame.image if conversion is None else cv2.cvtColor(frame.image, conversion)
        np.testing.assert_array_equal(ours.load_frame(k), expected)
    np.testing.assert_array_equal(ours.imu.t, [(m.timestamp - ours.clock_origin_ns // 1000) / 1e6 for m in readings])
    np.testing.assert_array_equal(
        ours.imu.gyro, np.deg2rad([[m.gyroscopeX, m.gyroscopeY, m.gyroscopeZ] for m in readings])
    )
    np.testing.assert_array_equal(
        ours.imu.acc, 9.80665 * np.array([[m.accelerometerX, m.accelerometerY, m.accelerometerZ] for m in readings])
    )


def test_a_damaged_event_packet_is_named(tmp_path):
    from eas_vo.datasets.aedat4_packets import Aedat4File

    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=random_stream(5000, seed=8), kind="events", packet=1000)
    packets = Aedat4File(path)
    offset, size = packets.streams["events"].packets[3]
    data = bytearray(path.read_bytes())
    data[offset + size // 2 : offset + size // 2 + 64] = bytes(64)  # zeros over the middle of packet 3's LZ4 frame
    path.write_bytes(bytes(data))
    with pytest.raises(DataError) as info:
        Aedat4Dataset(path, Aedat4Config(calibration=str(write_calib(tmp_path)))).events()
    message = str(info.value)
    assert (
        message.startswith(f"{path}:events: damaged AEDAT4 event packet 3 (at byte {offset - 8}): ")
        and "\n" not in message
    )


@pytest.mark.parametrize(
    "damage, what, shown, row",
    [
        ("back", "timestamp goes backwards", "", 700),
        ("off", f"pixel outside the {WIDTH}x{HEIGHT} sensor", f"({WIDTH}, ", 300),
    ],
)
def test_bad_events_name_the_event_and_lenient_drops_and_counts(tmp_path, damage, what, shown, row):
    t, x, y, p = (c.copy() for c in random_stream(1000, seed=3))
    if damage == "back":
        t[row] -= 500_000  # half a second back, inside one packet (the writer checks only between packets)
    else:
        x[row] = WIDTH
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=(t, x, y, p), kind="events")
    calib = str(write_calib(tmp_path))
    with pytest.raises(DataError) as info:
        Aedat4Dataset(path, Aedat4Config(calibration=calib)).events()
    assert str(info.value).startswith(f"{path}:events:{row}: {what}: {shown}")
    ds = Aedat4Dataset(path, Aedat4Config(calibration=calib, lenient=True))
    ev = ds.events()
    keep = np.arange(len(t)) != row
    np.testing.assert_array_equal(ev["x"], x[keep])
    np.testing.assert_array_equal(ev["t"], (t[keep] - ds.clock_origin_ns // 1000) / 1e6)
    assert ds.data_warnings() == [f"{path}:events: 1 dropped: {what} (first at event {row})"]


def test_frames_going_back_are_named_or_dropped(tmp_path):
    image = np.zeros((HEIGHT, WIDTH), np.uint8)
    # Starts in order (the writer wants that), middles not: the second's long exposure puts its
    # middle (1.051 s) after the third's (1.0025 s).
    frames = [(1_000_000, 1000, image), (1_001_000, 100_000, image + 1), (1_002_000, 1000, image + 2)]
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, frames=frames, kind="frames")
    calib = str(write_calib(tmp_path))
    with pytest.raises(DataError, match=r"rec.aedat4:frames:2: frame time 1.002500 s goes back \(previous 1.051000\)$"):
        Aedat4Dataset(path, Aedat4Config(calibration=calib))
    ds = Aedat4Dataset(path, Aedat4Config(calibration=calib, lenient=True))
    np.testing.assert_array_equal(ds.frame_times(), [1.0005, 1.051])
    assert ds.load_frame(1)[0, 0] == 1
    assert ds.data_warnings() == [f"{path}:frames: 1 dropped: frame time going back (first at frame 2)"]


def test_event_only_and_frame_only_recordings(tmp_path):
    from helpers import run_eas_vo

    calib = write_calib(tmp_path)
    events_only = tmp_path / "events.aedat4"
    events = random_stream(3000, seed=4)
    write_aedat4(events_only, events=events, kind="events")
    ds = Aedat4Dataset(events_only, Aedat4Config(calibration=str(calib), sample_rate_hz=10.0))
    assert ds.load_frame(0) is None and ds.imu is None and ds.ground_truth is None
    np.testing.assert_allclose(np.diff(ds.frame_times()), 0.1, rtol=0, atol=1e-6)  # (Unix seconds: ulp 2.4e-7 s)
    assert "events.aedat4 has no frames stream (an event-only recording)" in ds.no_frames_reason
    done = run_eas_vo(
        "run",
        "--dataset",
        str(events_only),
        "--frontend",
        "original",
        "--set",
        f"dataset.calibration={calib}",
        "--out",
        str(tmp_path / "out"),
        "--quiet",
    )
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert "needs APS frames" in done.stderr and "has no frames stream (an event-only recording)" in done.stderr

    frames_only = tmp_path / "frames.aedat4"
    image = np.full((HEIGHT, WIDTH), 7, np.uint8)
    write_aedat4(frames_only, frames=[(5_000_000 + 40_000 * k, 2000, image) for k in range(3)], kind="frames")
    ds = Aedat4Dataset(frames_only, Aedat4Config(calibration=str(calib)))
    assert len(ds.events()) == 0 and ds.events().dtype.names == ("t", "x", "y", "p")
    np.testing.assert_array_equal(ds.frame_times(), (5_001_000 + 40_000 * np.arange(3)) / 1e6)
    assert all(s.frame is not None and len(s.events_after) == 0 for s in ds.samples())


def test_ground_truth_from_a_tum_file_with_a_clock_offset(tmp_path):
    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=random_stream(10), kind="events")
    tum = tmp_path / "gt.tum"
    tum.write_text("# t px py pz qx qy qz qw\n10.0 1 2 3 0 0 0 1\n10.5 1 2 4 0 0 0.6 0.8\n")
    ds = Aedat4Dataset(
        path,
        Aedat4Config(
            calibration=str(write_calib(tmp_path)),
            ground_truth=str(tum),
            ground_truth_time_offset_s=1_700_000_000.0 - 10.0,
        ),
    )
    assert ds.clock_origin_ns == 1_700_000_000 * 10**9  # DV's Unix clock: times after its first second
    np.testing.assert_array_equal(ds.ground_truth.t, [0.0, 0.5])
    np.testing.assert_array_equal(ds.ground_truth.q_w_c[1], [0, 0, 0.6, 0.8])
    tum.write_text("10.0 1 2 3 0 0 0 1\n9.0 1 2 3 0 0 0 1\n")
    with pytest.raises(DataError, match=r"gt.tum:2: timestamp 9.000000000 does not increase"):
        Aedat4Dataset(path, Aedat4Config(calibration=str(write_calib(tmp_path)), ground_truth=str(tum)))


def test_truncated_files_are_named_errors_or_read_whole(tmp_path):
    """An AEDAT4 cut at any byte: a one-line error naming the file, or (accepted) exactly what the
    whole file holds: every event, frame and IMU reading."""
    from hypothesis import given
    from hypothesis import strategies as st

    from helpers import hostile_settings

    events = random_stream(4000, seed=5)
    t0 = int(events[0][0])
    image = np.random.default_rng(6).integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8)
    whole = tmp_path / "whole.aedat4"
    write_aedat4(
        whole,
        events=events,
        frames=[(t0 + 40_000 * k, 5000, image) for k in range(4)],
        imu=[(t0 + 5000 * k, 0.0, -1.0, 0.0, 1.0, 2.0, 3.0) for k in range(8)],
    )
    data = whole.read_bytes()
    config = Aedat4Config(calibration=str(write_calib(tmp_path)))
    expected = Aedat4Dataset(whole, config)
    cut = tmp_path / "cut.aedat4"

    @hostile_settings(60)
    @given(st.integers(0, len(data) - 1))
    def check(offset):
        cut.write_bytes(data[:offset])
        try:
            ds = Aedat4Dataset(cut, config)
            got = ds.events(), ds.frame_times(), [ds.load_frame(k) for k in range(len(ds.frame_times()))], ds.imu
        except DataError as exc:
            assert str(exc).startswith(str(cut)) and "\n" not in str(exc)
            return
        np.testing.assert_array_equal(got[0], expected.events())
        np.testing.assert_array_equal(got[1], expected.frame_times())
        assert all((frame == image).all() for frame in got[2])
        np.testing.assert_array_equal(got[3].gyro, expected.imu.gyro)

    check()


def structure_bytes(data: bytes, seed: int) -> list[int]:
    """Where an AEDAT4 file's structure is (found without the reader under test): each packet's
    8-byte header and the first and last 12 bytes of its body (a compressed frame's header and
    end, a FlatBuffer's offsets), 32 bytes of the index after the last packet, and 24 more
    anywhere; seeded."""
    import random
    import struct

    rng = random.Random(seed)
    at = 18 + struct.unpack_from("<i", data, 14)[0]  # magic (14 bytes), int32 header size, header
    places = set()
    while at + 8 <= len(data):
        size = struct.unpack_from("<ii", data, at)[1]
        if size < 0 or at + 8 + size > len(data):
            break  # the index: not a packet
        body = range(at + 8, at + 8 + size)
        places.update(range(at, at + 8), body[:12], body[-12:])
        at += 8 + size
    places.update(rng.sample(range(at, len(data)), min(32, len(data) - at)))
    places.update(rng.sample(range(len(data)), 24))
    return sorted(places)


@pytest.mark.parametrize("compression", ["LZ4", "ZSTD", "NONE"])
def test_a_flipped_bit_is_a_one_line_error_naming_the_packet_or_a_read(tmp_path, compression):
    """One bit flipped in an AEDAT4's structure (packet headers, the ends of every packet of
    every stream, the index) and anywhere: a one-line error naming the file (and for a packet,
    the stream and the packet) or a whole read, each within seconds, never a spin or a crash
    (dv-processing, given such files, spun for minutes holding the GIL, so that Ctrl-C and
    SIGTERM were never seen, or crashed)."""
    from helpers import flipped_copies, read_each_bounded

    rng = np.random.default_rng(2)
    t, x, y, p = random_stream(200, seed=11)
    image = rng.integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8)
    path = tmp_path / "rec.aedat4"
    write_aedat4(
        path,
        events=(t, x, y, p),
        frames=[(t[0] + 40_000 * k, 5000, image) for k in range(2)],
        imu=[(t[0] + 5000 * k, 0.0, -1.0, 0.0, 1.0, 2.0, 3.0) for k in range(4)],
        compression=compression,
        packet=100,
    )
    rng_bits = np.random.default_rng(3)
    flips = [("", at, int(rng_bits.integers(8))) for at in structure_bytes(path.read_bytes(), seed=4)]
    copies = flipped_copies(path, tmp_path / "flips", flips)
    outcomes = read_each_bounded([path, *copies], [f"dataset.calibration={write_calib(tmp_path)}"])
    assert outcomes[str(path)] == "ok"
    for copy in copies:
        outcome = outcomes[str(copy)]
        assert outcome == "ok" or outcome.startswith(str(copy)), (copy, outcome)
        if " packet " in outcome and "AEDAT4" in outcome:
            assert re.match(
                rf"{re.escape(str(copy))}:(events|frames|imu)(:\d+)?: damaged AEDAT4 "
                r"(event|frame|IMU) packet \d+ \(at byte \d+\): ",
                outcome,
            ), outcome


#: A CLI run whose event packets each take 0.3 s to decode (a sleep, which releases the GIL as
#: cramjam's decoders do), one packet a task, saying on stderr when the first starts.
SLOW_READ = """
import sys, time
from eas_vo.datasets import aedat4, aedat4_packets
aedat4.GROUP_BYTES = 1
decode = aedat4_packets.Aedat4File.event_records
def slow(self, k, scratch=None):
    sys.stderr.write("decoding\\n")  # one write: the two threads' lines never interleave
    time.sleep(0.3)
    return decode(self, k, scratch)
aedat4_packets.Aedat4File.event_records = slow
from eas_vo.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("signum, status", [("SIGTERM", 143), ("SIGINT", 130)])
def test_sigterm_and_ctrl_c_end_a_long_read_at_once(tmp_path, signum, status):
    """`eas-vo info` reading an AEDAT4's events (40 packets, 12 s here) ends within seconds of
    SIGTERM or Ctrl-C with the usual line, its exit status saying which: the reader's waits on
    its worker threads are interruptible and no task outlives the interrupt by more than its
    own packet."""
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "rec.aedat4"
    write_aedat4(path, events=random_stream(4000, seed=12), kind="events", packet=100)
    child = subprocess.Popen(
        [
            sys.executable,
            "-c",
            SLOW_READ,
            "info",
            "--dataset",
            str(path),
            "--set",
            f"dataset.calibration={write_calib(tmp_path)}",
        ],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stderr.readline() == "decoding\n"
        sent = time.monotonic()
        child.send_signal(getattr(signal, signum))
        _, err = child.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        child.kill()
    assert child.returncode == status, err
    assert [line for line in err.splitlines() if line != "decoding"] == [
        "eas-vo info: interrupted; nothing was written"
    ], err
    assert took < 5, f"{took:.1f} s from the signal to the end"  # 12 s if the read went on


def test_damaged_event_packets_are_read_within_their_bytes(tmp_path, monkeypatch):
    """The compiled FlatBuffer walk of an event packet (_event_vector), run as plain Python
    (numpy's indexing raises on any read outside the bytes), on real packets cut short, with
    bytes overwritten or random: it never reads outside them, gives what the compiled walk
    gives, and an accepted packet's events lie inside it; the real packet gives the events
    dv-processing wrote."""
    from hypothesis import given
    from hypothesis import strategies as st

    from eas_vo.datasets import aedat4_packets
    from eas_vo.datasets.aedat4_packets import PACKET_EVENT, Aedat4File, _event_vector
    from helpers import hostile_settings

    path = tmp_path / "rec.aedat4"
    events = random_stream(300, seed=9)
    write_aedat4(path, events=events, kind="events", compression="NONE", packet=300)
    packets = Aedat4File(path)
    offset, size = packets.streams["events"].packets[0]
    body = np.array(np.frombuffer(path.read_bytes()[offset : offset + size], np.uint8))
    status, start, count = _event_vector(body)
    assert status == 0 and count == 300
    np.testing.assert_array_equal(np.frombuffer(body, PACKET_EVENT, count, start)["t"], events[0])
    monkeypatch.setattr(aedat4_packets, "_uint", aedat4_packets._uint.py_func)  # its reads checked too (compiled above)

    @hostile_settings(300)
    @given(st.data())
    def check(data):
        kind = data.draw(st.sampled_from(["cut", "overwrite", "random"]))
        if kind == "random":
            damaged = np.array(np.frombuffer(data.draw(st.binary(max_size=64)), np.uint8))  # writable, as compiled
        else:
            damaged = body.copy()
            if kind == "cut":
                damaged = damaged[: data.draw(st.integers(0, len(body) - 1))]
            else:
                at = data.draw(st.integers(0, 40))
                damaged[at : at + 4] = np.frombuffer(data.draw(st.binary(min_size=4, max_size=4)), np.uint8)[
                    : len(damaged[at : at + 4])
                ]
        status, a, b = _event_vector.py_func(damaged)  # an IndexError here is a read outside the bytes
        assert (status, a, b) == _event_vector(damaged)
        if status == 0:
            assert a + 16 * b <= len(damaged)

    check()


# -- the same sequence as an ECD folder and as an AEDAT4 --------------------------------------


def write_ecd_as_aedat4(ecd, path, exposure_us):
    """An ECD sequence as a DAVIS would have recorded it in DV: microsecond timestamps, frames
    stamped at the start of an exposure of `exposure_us` centred on the ECD's frame time,
    IMU in g and deg/s (dv-processing stores them as float32)."""
    ev = ecd.events()
    frames = [
        (round(t * 1e6) - exposure_us // 2, exposure_us, ecd.load_frame(k)) for k, t in enumerate(ecd.frame_times())
    ]
    imu = np.column_stack([np.round(ecd.imu.t * 1e6), ecd.imu.acc / 9.80665, np.degrees(ecd.imu.gyro)])
    write_aedat4(
        path,
        events=(np.round(ev["t"] * 1e6).astype(np.int64), ev["x"], ev["y"], ev["p"]),
        frames=frames,
        imu=imu.tolist(),
        size=(ecd.camera.width, ecd.camera.height),
    )


@pytest.fixture(scope="module")
def both_formats(tmp_path_factory):
    """`eas-vo simulate --duration 1` (ECD folder `sim`); the same with its nanosecond event times
    rounded to the microseconds an AEDAT4 holds and its IMU to the float32 g and deg/s it holds
    (`sim_us`, every digit kept); that written to AEDAT4 by dv-processing (`sim.aedat4`)."""
    from eas_vo.datasets.ecd import EcdFolderDataset, write_ecd_folder
    from eas_vo.datasets.simulator import SimConfig
    from helpers import run_eas_vo

    root = tmp_path_factory.mktemp("aedat4_identity")
    done = run_eas_vo("simulate", "--out", str(root / "sim"), "--duration", "1")
    assert done.returncode == 0, done.stderr
    sim = EcdFolderDataset(root / "sim")
    events = sim.events().copy()
    events["t"] = np.round(events["t"] * 1e6) / 1e6
    frames = [sim.load_frame(k) for k in range(len(sim.frame_times()))]
    # The IMU as the AEDAT4 reader gives it back (float32 g and deg/s, converted in float64),
    # written with every digit (the ECD writer's 9 decimals would round it).
    stored = (
        np.float32(sim.imu.acc / 9.80665).astype(np.float64),
        np.float32(np.degrees(sim.imu.gyro)).astype(np.float64),
    )
    imu = ImuSeries(sim.imu.t, stored[0] * 9.80665, np.deg2rad(stored[1]))
    write_ecd_folder(root / "sim_us", sim.camera, sim.frame_times(), frames, events, sim.ground_truth, imu)
    table = np.column_stack([imu.t, imu.acc, imu.gyro])
    (root / "sim_us" / "imu.txt").write_text(
        "".join(" ".join(np.format_float_positional(v, unique=True) for v in row) + "\n" for row in table)
    )
    write_ecd_as_aedat4(EcdFolderDataset(root / "sim_us"), root / "sim.aedat4", round(SimConfig().aps.exposure_s * 1e6))
    return root


def test_an_aedat4_holds_what_the_ecd_folder_holds(both_formats):
    from eas_vo.datasets.ecd import EcdFolderDataset

    root = both_formats
    sim = EcdFolderDataset(root / "sim")
    ds = Aedat4Dataset(
        root / "sim.aedat4",
        Aedat4Config(calibration=str(root / "sim" / "calib.txt"), ground_truth=str(root / "sim" / "groundtruth.txt")),
    )
    assert (ds.camera.width, ds.camera.height, ds.camera.model) == (
        sim.camera.width,
        sim.camera.height,
        sim.camera.model,
    )
    np.testing.assert_array_equal(ds.camera.K, sim.camera.K)
    np.testing.assert_array_equal(ds.camera.dist, sim.camera.dist)
    ours, theirs = ds.events(), sim.events()
    assert len(ours) == len(theirs) > 100_000
    np.testing.assert_array_equal(
        np.round(ours["t"] * 1e6).astype(np.int64), np.round(theirs["t"] * 1e6).astype(np.int64)
    )
    for name in ("x", "y", "p"):
        np.testing.assert_array_equal(ours[name], theirs[name])
    np.testing.assert_array_equal(np.round(ds.frame_times() * 1e6), np.round(sim.frame_times() * 1e6))
    np.testing.assert_array_equal(ds.frame_times(), sim.frame_times())
    for k in range(len(sim.frame_times())):
        np.testing.assert_array_equal(ds.load_frame(k), sim.load_frame(k))
    np.testing.assert_array_equal(ds.imu.t, sim.imu.t)
    np.testing.assert_allclose(ds.imu.acc, sim.imu.acc, rtol=2e-7)  # float32 in the file: 6e-8 apart
    np.testing.assert_allclose(ds.imu.gyro, sim.imu.gyro, rtol=2e-7)
    for field in ("t", "p_w_c", "q_w_c"):
        np.testing.assert_array_equal(getattr(ds.ground_truth, field), getattr(sim.ground_truth, field))


@pytest.mark.parametrize("config", ["paper", "best"])
def test_paper_and_best_runs_give_the_same_trajectory_from_both(both_formats, tmp_path, config):
    from helpers import run_eas_vo

    root = both_formats
    ecd = run_eas_vo(
        "run", "--config", config, "--dataset", str(root / "sim_us"), "--out", str(tmp_path / "ecd"), "--quiet"
    )
    aedat = run_eas_vo(
        "run",
        "--config",
        config,
        "--dataset",
        str(root / "sim.aedat4"),
        "--set",
        f"dataset.calibration={root / 'sim' / 'calib.txt'}",
        "--set",
        f"dataset.ground_truth={root / 'sim' / 'groundtruth.txt'}",
        "--out",
        str(tmp_path / "aedat"),
        "--quiet",
    )
    assert ecd.returncode == 0 and aedat.returncode == 0, ecd.stderr + aedat.stderr
    for name in ("trajectory.tum", "groundtruth.tum"):
        a, b = (np.loadtxt(tmp_path / run / name) for run in ("ecd", "aedat"))
        assert a.shape == b.shape == (20, 8)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-6)
    metrics = [json.loads((tmp_path / run / "metrics.json").read_text()) for run in ("ecd", "aedat")]
    assert metrics[1]["nc_mean"] == metrics[0]["nc_mean"] and metrics[1]["status_counts"] == metrics[0]["status_counts"]
    assert metrics[1]["ape_mean_rad"] == pytest.approx(metrics[0]["ape_mean_rad"], abs=1e-6)
