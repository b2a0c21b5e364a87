"""Every stream's clock in seconds: a stream whose timestamps are in microseconds or
nanoseconds beside the others' seconds (events, frames, IMU or ground truth; ECD folders and
zips, MVSEC HDF5, a dataset.ground_truth TUM file) is refused by a run with one line naming
its file and the unit, and `info` warns, whatever the clock's origin."""

from __future__ import annotations

import shutil

import pytest

from eas_vo.config import resolve
from eas_vo.datasets import recording
from eas_vo.datasets.ecd import EcdFolderDataset
from eas_vo.sequence.info import describe
from helpers import ECD_FILES, UNIX_S, known_sequence, one_line_failure, retimed, sequence_with, write_mvsec

UNITS = {"microseconds": 10**6, "nanoseconds": 10**9}


@pytest.mark.parametrize("shift_s", [0, UNIX_S], ids=["zero", "unix"])
@pytest.mark.parametrize("unit", sorted(UNITS))
@pytest.mark.parametrize("stream", sorted(ECD_FILES))
def test_a_stream_in_another_unit_is_refused_naming_its_file(tmp_path, capsys, stream, unit, shift_s):
    folder = sequence_with(tmp_path / "seq", stream, UNITS[unit], shift_s)
    err = one_line_failure(["run", "--dataset", str(folder), "--out", str(tmp_path / "run")], capsys)
    assert f"{folder / ECD_FILES[stream]}: the {stream} timestamps span" in err and f"look like {unit}" in err, err
    warnings = describe(resolve(None, {"dataset": str(folder)})).warnings
    assert [w for w in warnings if "look like" in w] == [err.removeprefix("eas-vo: error: ").strip()]


def test_streams_in_seconds_pass_whatever_their_lengths_and_origin(tmp_path):
    """An excerpt keeps a part of a stream beside all of another (the real shapes_rotation: 0.5 s
    of events, 30 s of frames): spans a hundred times apart are no unit."""
    folder = sequence_with(tmp_path / "seq", None, 1, UNIX_S)
    events = (folder / "events.txt").read_text().splitlines()
    (folder / "events.txt").write_text("\n".join(events[:50]) + "\n")  # 6 ms of the 0.6 s
    dataset = EcdFolderDataset(str(folder))
    assert dataset.clock_origin_ns == UNIX_S * 10**9
    assert recording.recording_clock_problems(dataset, has_frames=True) == {}


def test_the_odd_stream_out_is_named_when_the_frames_are_in_microseconds(tmp_path):
    folder = sequence_with(tmp_path / "seq", "frame", 10**6)
    problems = recording.recording_clock_problems(EcdFolderDataset(str(folder)), has_frames=True)
    assert list(problems) == ["frame"] and "look like microseconds" in problems["frame"]


@pytest.mark.parametrize("door", ["folder", "zip"])
def test_event_only_microseconds_are_refused_before_any_sample_is_made(tmp_path, capsys, monkeypatch, door):
    """Alone, a stream is refused when it spans more than a day; the samples of an event-only
    stream (one every 50 ms: 12 million over 6e5 s) are never made."""
    folder = tmp_path / "seq"
    known_sequence(folder, frames=False)
    for file in ("imu.txt", "groundtruth.txt"):
        (folder / file).unlink()
    retimed(folder / "events.txt", 10**6)
    location = folder if door == "folder" else shutil.make_archive(str(tmp_path / "seq"), "zip", folder)

    def no_sampling(*args):
        raise AssertionError("samples made from events in microseconds")

    monkeypatch.setattr(recording, "event_sample_times", no_sampling)
    sensor = ["--set", "dataset.width=346", "--set", "dataset.height=260"]
    err = one_line_failure(
        [
            "run",
            "--dataset",
            str(location),
            "--tracker",
            "cmax",
            "--frontend",
            "none",
            *sensor,
            "--out",
            str(tmp_path / "run"),
        ],
        capsys,
    )
    assert "events.txt: the event timestamps span" in err and "more than a day" in err, err
    info = describe(resolve(None, {"dataset": str(location)}, [sensor[1], sensor[3]]))
    assert info.samples.count == 0 and [w for w in info.warnings if "more than a day" in w] == [
        err[len("eas-vo: error: ") : -1]
    ]
    assert (
        one_line_failure(["convert", "--dataset", str(location), *sensor, "--out", str(tmp_path / "copy")], capsys)
        == err
    )


def test_mvsec_pose_ts_in_microseconds_is_refused(tmp_path, capsys):
    base = EcdFolderDataset(str(known_sequence(tmp_path / "seq")))
    gt = base.ground_truth
    base.ground_truth = type(gt)(gt.t * 1e6, gt.p_w_c, gt.q_w_c)
    data = write_mvsec(tmp_path / "mvsec", base)
    err = one_line_failure(
        [
            "run",
            "--dataset",
            str(data),
            "--set",
            f"dataset.calibration={tmp_path / 'seq' / 'calib.txt'}",
            "--out",
            str(tmp_path / "run"),
        ],
        capsys,
    )
    assert f"{tmp_path / 'mvsec' / 'seq_gt.hdf5'}:davis/left/pose_ts: the ground-truth timestamps span" in err, err
    assert "look like microseconds" in err


def test_a_ground_truth_file_in_microseconds_is_refused_naming_it(tmp_path, capsys):
    """dataset.ground_truth (the TUM file beside an AEDAT4 or a bag, or instead of a folder's own)."""
    folder = known_sequence(tmp_path / "seq")
    tum = tmp_path / "poses.tum"
    shutil.copy(folder / "groundtruth.txt", tum)
    retimed(tum, 10**6, UNIX_S)
    err = one_line_failure(
        ["run", "--dataset", str(folder), "--set", f"dataset.ground_truth={tum}", "--out", str(tmp_path / "run")],
        capsys,
    )
    assert f"{tum}: the ground-truth timestamps span" in err and "look like microseconds" in err, err


def test_clock_unit_problems_name_the_unit_the_ratio_suggests():
    spans = {"frame": 2.0, "event": 2.0, "IMU": 2e9, "ground-truth": 2.1}
    problems = recording.clock_unit_problems(spans, {})
    assert list(problems) == ["IMU"] and "look like nanoseconds" in problems["IMU"]
    assert recording.clock_unit_problems({"frame": 30.0, "event": 30.0 / 1e4}, {}) == {}


def test_events_on_another_clock_than_the_frames_are_refused_naming_both(tmp_path, capsys):
    """Events at Unix time beside frames from zero (spans alike, no unit to see): a run is refused
    in one line naming events.txt and images.txt, and `info` warns the same."""
    folder = sequence_with(tmp_path / "seq", None, 1)
    retimed(folder / ECD_FILES["event"], 1, UNIX_S)
    err = one_line_failure(["run", "--dataset", str(folder), "--out", str(tmp_path / "run")], capsys)
    assert (
        f"{folder / ECD_FILES['event']}: the events (" in err and "do not overlap" in err and ECD_FILES["frame"] in err
    ), err
    warnings = describe(resolve(None, {"dataset": str(folder)})).warnings
    assert [w for w in warnings if "do not overlap" in w] == [err.removeprefix("eas-vo: error: ").strip()]
