"""Recordings as real cameras and tools write them (../shared/data/real_files): the test bags of
the ROS event_camera_py package, an iniVation DAVIS346 (`libcaer_cmp`) and a Prophesee camera
(`evt3`), with Unix clocks, no CameraInfo, no frames, an mcap bag whose metadata names no
storage plugin: each opens, `info` says what it holds and what a run misses, and an event-only
run goes through with a calibration given."""

from __future__ import annotations

import json

import pytest

from eas_vo.registry import open_dataset
from helpers import EVENT_CAMERA_PY, require, run_eas_vo

#: Each recording: its sensor, encoding, event count (event_camera_py's tests state them: OFF + ON)
#: and where its clock starts [s] (the first event's whole second).
RECORDINGS = {
    "test_events_1": ((640, 480), "evt3", 218291 + 125183, 1675956550),
    "test_events_1.bag": ((640, 480), "evt3", 218291 + 125183, 1675956550),
    "test_events_2": ((346, 260), "libcaer_cmp", 360223 + 211043, 1744227144),
}


def pinhole_calib(folder, width, height):
    """An ECD calib.txt of a 70-degree-wide pinhole lens for the sensor (no calibration ships
    with these recordings)."""
    path = folder / "calib.txt"
    f = width / 2 / 0.7002  # tan(35 deg)
    path.write_text(f"{f:.3f} {f:.3f} {width / 2} {height / 2} 0 0 0 0 0\n")
    return path


@pytest.mark.parametrize("name", sorted(RECORDINGS))
def test_info_says_what_the_file_holds_then_what_a_run_misses(name):
    path = require(EVENT_CAMERA_PY / name)
    sensor, encoding, count, origin_s = RECORDINGS[name]
    done = run_eas_vo("info", "--dataset", str(path))
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "topic /event_camera/events: event_camera_msgs/msg/EventPacket" in out
    assert f"event encoding {encoding}" in out and f"sensor        {sensor[0]} x {sensor[1]} px" in out
    assert f"  events        {count} events" in out
    assert f"after {origin_s} s of the recording's clock" in out
    assert "camera        unknown (no calibration)" in out
    assert (
        "to run        " in out
        and "holds no CameraInfo message: give the intrinsics with --set dataset.calibration=FILE" in out
    )
    ds = open_dataset(str(path), need_camera=False)
    assert ds.clock_origin_ns == origin_s * 10**9 and ds.camera is None and ds.sensor_size == sensor


@pytest.mark.parametrize("name", ["test_events_1", "test_events_2"])  # (the .bag holds test_events_1's packets)
def test_without_a_calibration_a_run_is_one_line_with_one_a_run_goes_through(name, tmp_path):
    path = require(EVENT_CAMERA_PY / name)
    sensor = RECORDINGS[name][0]
    refused = run_eas_vo("run", "--dataset", str(path), "--tracker", "cmax", "--out", str(tmp_path / "no"), "--quiet")
    assert refused.returncode == 1 and refused.stderr.count("\n") == 1, refused.stderr
    assert "--set dataset.calibration=FILE" in refused.stderr and not (tmp_path / "no").exists()
    calib = pinhole_calib(tmp_path, *sensor)
    done = run_eas_vo(
        "run",
        "--dataset",
        str(path),
        "--tracker",
        "cmax",
        "--set",
        f"dataset.calibration={calib}",
        "--set",
        "run.duration_s=0.15",
        "--out",
        str(tmp_path / "run"),
        "--quiet",
    )
    assert done.returncode == 0, done.stderr
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["frames"] >= 3
    first = (tmp_path / "run" / "trajectory.tum").read_text().split()[0]
    assert first.startswith(str(RECORDINGS[name][3])[:9])  # the file's times are the recording's own (Unix)
