"""describe and convert on sequences of known content: one written by the ECD writer at
346x260 (every count, span and rate known), the simulated 240x180 one, and an event-only one."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from eas_vo.camera import CameraModel
from eas_vo.config import resolve
from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.errors import DataError, EasVoError
from eas_vo.sequence.convert import convert
from eas_vo.sequence.info import describe
from helpers import (
    FRAME_HZ,
    FRAME_T0,
    N_EVENTS,
    N_FRAMES,
    N_POSES,
    N_READINGS,
    SHAPES_ROTATION,
    known_sequence,
    require,
)

#: How an event-only folder of the written sequence is opened: its sensor size is not in it.
SENSOR = ("dataset.width=346", "dataset.height=260")


def config_for(folder: Path, *assignments: str, **run):
    return resolve(None, {"dataset": str(folder), **run}, list(assignments))


def opened(folder: Path, *assignments: str) -> EcdFolderDataset:
    return EcdFolderDataset(str(folder), config_for(folder, *assignments).dataset)


@pytest.mark.parametrize("width, height", [(346, 260), (640, 480)])
def test_describe_gives_every_stream_its_count_span_and_rate(tmp_path, width, height):
    info = describe(config_for(known_sequence(tmp_path / "seq", width, height)))
    assert (info.camera.width, info.camera.height, info.plugin) == (width, height, "ecd")
    assert info.camera.K[0, 0] == pytest.approx(0.8 * width, rel=1e-12)
    assert info.frames.count == N_FRAMES and info.frames.t0_s == FRAME_T0
    assert info.frames.rate_hz == pytest.approx(FRAME_HZ, rel=1e-9)
    assert info.events.count == N_EVENTS and 0.4 <= info.events.t0_s < info.events.t1_s < 1.0
    assert (info.imu.count, info.ground_truth.count) == (N_READINGS, N_POSES)
    assert info.imu.rate_hz == pytest.approx(250.0, rel=1e-9) and info.ground_truth.rate_hz == pytest.approx(
        200.0, rel=1e-9
    )
    assert info.span.t0_s == info.events.t0_s and info.span.t1_s == info.imu.t1_s == 0.42 + (N_READINGS - 1) / 250.0
    text = "\n".join(info.lines())
    for says in (
        f"{width} x {height} px",
        "frames, events, IMU, ground truth",
        f"{N_FRAMES} APS frames",
        "25 Hz",
        f"{N_EVENTS} events",
        f"{N_READINGS} readings",
        "250 Hz",
        f"{N_POSES} poses",
        "200 Hz",
        "radtan lens",
    ):
        assert says in text, (says, text)


def test_describe_decodes_at_most_one_frame(tmp_path, monkeypatch):
    folder = known_sequence(tmp_path / "seq")
    decoded = []
    decode = EcdFolderDataset._decode_frame
    monkeypatch.setattr(EcdFolderDataset, "_decode_frame", lambda self, k: decoded.append(k) or decode(self, k))
    assert describe(config_for(folder)).frames.count == N_FRAMES
    assert len(decoded) <= 1


def test_describe_an_event_only_stream_says_why_it_has_no_frames(tmp_path):
    info = describe(config_for(known_sequence(tmp_path / "seq", frames=False), *SENSOR))
    assert info.frames is None and "images.txt does not exist" in info.no_frames_reason
    assert info.events.count == N_EVENTS and info.samples.count > 1
    text = "\n".join(info.lines())
    assert "streams       events, IMU, ground truth" in text and "frames        none: " in text


def assert_same_recording(a: EcdFolderDataset, b: EcdFolderDataset, frames: list[int] | None = None) -> None:
    """The streams of `b` equal those of `a` exactly (its frames `frames`, default all)."""
    frames = list(range(len(a.frame_times()))) if frames is None else frames
    assert np.array_equal(b.frame_times(), a.frame_times()[frames])
    for k_b, k_a in enumerate(frames):
        assert np.array_equal(b.load_frame(k_b), a.load_frame(k_a))
    for name in ("width", "height", "model"):
        assert getattr(b.camera, name) == getattr(a.camera, name)
    assert np.array_equal(b.camera.K, a.camera.K) and np.array_equal(b.camera.dist, a.camera.dist)


def test_convert_gives_back_every_file_of_a_simulated_sequence(short_sequence, tmp_path):
    out = tmp_path / "converted"
    done = convert(config_for(short_sequence), out)
    for name in ("events.txt", "images.txt", "imu.txt", "groundtruth.txt", "calib.txt"):
        assert (out / name).read_bytes() == (short_sequence / name).read_bytes(), name
    a, b = opened(short_sequence), opened(out)
    assert_same_recording(a, b)
    assert np.array_equal(b.events(), a.events())
    assert np.array_equal(b.imu.gyro, a.imu.gyro) and np.array_equal(b.ground_truth.q_w_c, a.ground_truth.q_w_c)
    assert (done.frames, done.events, done.imu, done.poses) == (
        len(a.frame_times()),
        len(a.events()),
        len(a.imu.t),
        len(a.ground_truth.t),
    )


def test_convert_reads_the_written_text_back_exactly(tmp_path, monkeypatch):
    """Parsed afresh (an empty event cache): the same events, poses and readings as the source."""
    source = known_sequence(tmp_path / "seq")
    convert(config_for(source), tmp_path / "out")
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(tmp_path / "fresh_cache"))
    a, b = opened(source), opened(tmp_path / "out")
    assert_same_recording(a, b)
    assert np.array_equal(b.events(), a.events())
    for field in ("t", "p_w_c", "q_w_c"):
        assert np.array_equal(getattr(b.ground_truth, field), getattr(a.ground_truth, field))
    for field in ("t", "acc", "gyro"):
        assert np.array_equal(getattr(b.imu, field), getattr(a.imu, field))


def test_convert_of_a_window_keeps_its_frames_and_the_streams_between_its_neighbours(tmp_path):
    source = known_sequence(tmp_path / "seq")
    done = convert(config_for(source, start_s=0.1, duration_s=0.2), tmp_path / "out")
    a, b = opened(source), opened(tmp_path / "out")
    times = a.frame_times()
    window = [k for k, t in enumerate(times) if times[0] + 0.1 <= t < times[0] + 0.3]
    assert window == [3, 4, 5, 6, 7] and done.frames == 5
    assert_same_recording(a, b, window)
    lo, hi = times[window[0] - 1], times[window[-1] + 1]
    events = a.events()
    assert np.array_equal(b.events(), events[(events["t"] >= lo) & (events["t"] < hi)])
    for got, source in ((b.ground_truth.t, a.ground_truth.t), (b.imu.t, a.imu.t)):
        inside = np.flatnonzero((source >= lo) & (source < hi))
        assert np.array_equal(got, source[inside[0] - 1 : inside[-1] + 2])  # and one more at each end
    assert np.array_equal(b.ground_truth.q_w_c, a.ground_truth.q_w_c[np.isin(a.ground_truth.t, b.ground_truth.t)])
    assert np.array_equal(b.imu.gyro, a.imu.gyro[np.isin(a.imu.t, b.imu.t)])
    assert done.imu == len(b.imu.t) and done.poses == len(b.ground_truth.t)
    assert done.span_s == pytest.approx(4 / FRAME_HZ)


def test_convert_of_an_event_only_stream_writes_no_frame_list(tmp_path):
    source = known_sequence(tmp_path / "seq", frames=False)
    done = convert(config_for(source, *SENSOR), tmp_path / "out")
    assert not (tmp_path / "out" / "images.txt").exists() and not (tmp_path / "out" / "images").exists()
    assert (tmp_path / "out" / "events.txt").read_bytes() == (source / "events.txt").read_bytes()
    assert done.frames == 0 and done.events == N_EVENTS and done.sensor == (346, 260)
    assert np.array_equal(opened(tmp_path / "out", *SENSOR).frame_times(), opened(source, *SENSOR).frame_times())


def test_convert_writes_nothing_when_a_frame_cannot_be_read(tmp_path):
    source = known_sequence(tmp_path / "seq")
    (source / "images" / "frame_00000005.png").write_bytes(b"not a png")
    with pytest.raises(DataError, match=r"frame_00000005\.png: cannot decode frame 5 \(images.txt line 6\)"):
        convert(config_for(source), tmp_path / "out")
    assert sorted(os.listdir(tmp_path)) == ["seq"]  # neither the folder nor a staging one or a lock


def test_convert_writes_a_fisheye_as_a_kalibr_camchain(tmp_path, monkeypatch):
    """calib.txt holds only radial-tangential coefficients: an equidistant lens goes into the
    folder's camchain.yaml, and the converted folder reads back the same camera."""
    from eas_vo import registry

    source = known_sequence(tmp_path / "seq")
    fisheye = opened(source)
    dist = np.array([-0.048, 0.0113, -0.0554, 0.0215])
    fisheye.camera = CameraModel(fisheye.camera.width, fisheye.camera.height, fisheye.camera.K, dist, "equidistant")
    monkeypatch.setattr(registry, "open_dataset", lambda spec, config=None: fisheye)
    convert(config_for(source), tmp_path / "out")
    assert not (tmp_path / "out" / "calib.txt").exists()
    monkeypatch.undo()
    back = opened(tmp_path / "out").camera
    assert back.model == "equidistant"
    np.testing.assert_array_equal(back.dist, dist)
    np.testing.assert_array_equal(back.K, fisheye.camera.K)


def test_convert_refuses_events_before_time_zero(tmp_path, monkeypatch):
    from eas_vo import registry

    source = known_sequence(tmp_path / "seq")
    early = opened(source)
    events = early.events().copy()
    events["t"] -= 0.45  # the first at -0.05 s
    monkeypatch.setattr(early, "events", lambda: events)
    monkeypatch.setattr(registry, "open_dataset", lambda spec, config=None: early)
    with pytest.raises(EasVoError, match=r"its events start at -0\.04\d+ s; events.txt cannot hold negative times"):
        convert(config_for(source), tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_convert_of_the_real_excerpt_keeps_its_events_and_frames_and_its_poses_to_9_decimals(tmp_path):
    source = require(SHAPES_ROTATION)
    convert(config_for(source, duration_s=5.0), tmp_path / "out")
    a, b = opened(source), opened(tmp_path / "out")
    window = list(a.window(0.0, 5.0))
    assert_same_recording(a, b, window)
    assert np.array_equal(b.events(), a.events())  # the excerpt's events end long before 5 s
    kept = np.isin(a.ground_truth.t, b.ground_truth.t)
    half_ninth_decimal = 5.01e-10  # its 11-12 decimals rounded to 9 (and the parse's own 1e-16)
    np.testing.assert_allclose(b.ground_truth.q_w_c, a.ground_truth.q_w_c[kept], rtol=0, atol=half_ninth_decimal)
    np.testing.assert_allclose(b.ground_truth.p_w_c, a.ground_truth.p_w_c[kept], rtol=0, atol=half_ninth_decimal)


def test_a_ground_truth_on_another_clock_is_said_to_overlap_nothing_and_a_run_names_the_key(sequence_copy, tmp_path):
    """Poses stamped in Unix seconds beside frames from 0: info says the ground truth covers none
    of the frames (both spans), and a run stops before any work naming
    dataset.ground_truth_time_offset_s and the offset that starts both together."""
    from helpers import run_eas_vo

    gt = sequence_copy / "groundtruth.txt"
    lines = gt.read_text().splitlines()
    first = float(lines[0].split()[0])
    gt.write_text(
        "".join(
            f"{int(t.split('.')[0]) + 1_700_000_000}.{t.split('.')[1]} {rest}\n"
            for t, rest in (line.split(" ", 1) for line in lines)
        )
    )
    info = describe(resolve(None, {"dataset": str(sequence_copy)}))
    overlap = next(line for line in info.lines() if line.lstrip().startswith("overlap"))
    assert (
        "ground truth NONE (1700000000." in overlap and "another clock? dataset.ground_truth_time_offset_s" in overlap
    )
    assert any("the ground truth overlaps none of the samples" in line for line in info.lines())
    done = run_eas_vo("run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "run"), "--quiet")
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    offset = float(done.stderr.split("S = ")[1].split()[0])
    assert "--set dataset.ground_truth_time_offset_s=S" in done.stderr and not (tmp_path / "run").exists()
    assert offset == pytest.approx(EcdFolderDataset(sequence_copy).frame_times()[0] - (first + 1_700_000_000), abs=1e-5)
