"""Event-only streams, the estimated time offset, and --lenient through the CLI."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import EVENT_WINDOWS, SHAPES_ROTATION, require
from eas_vo import config, pipeline
from eas_vo.cli import main
from eas_vo.datasets.ecd import EcdConfig, EcdFolderDataset, event_sample_times
from eas_vo.evaluation import estimate_time_offset
from eas_vo.geometry import quats_from_matrices
from eas_vo.types import PoseSeries, RelativeRotation


def test_event_sample_times_by_rate_and_by_count():
    t = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(event_sample_times(t, 10.0, 0), np.arange(0, 1.0, 0.1))
    np.testing.assert_array_equal(event_sample_times(t, 10.0, 250), t[::250])
    assert len(event_sample_times(t[:0], 10.0, 0)) == 0


@pytest.mark.parametrize("name", ["boxes_rotation", "poster_rotation", "dynamic_rotation"])
def test_event_only_real_windows_run_the_slice_frontend(name):
    folder = require(EVENT_WINDOWS / name)
    ds = EcdFolderDataset(folder, EcdConfig(sample_every_events=3000))
    assert ds.load_frame(0) is None and len(ds.events()) == 30_000
    assert len(ds.frame_times()) == 10
    cfg = config.resolve(None, {"dataset": str(folder), "frontend": "slice"}, ["dataset.sample_every_events=3000", "frontend.n=3000"])
    result = pipeline.run(cfg)
    assert result.metrics["frames"] == 10 and result.metrics["nc_mean"] > 50
    assert result.errors is None and np.isfinite(result.R_w_c).all()


def test_frame_frontend_on_an_event_only_stream_is_a_clear_error(capsys):
    folder = require(EVENT_WINDOWS / "boxes_rotation")
    assert main(["run", "--dataset", str(folder), "--frontend", "eas"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs APS frames" in err and "images.txt does not exist" in err


def test_time_offset_known_answer():
    rng = np.random.default_rng(0)
    t_gt = np.arange(0, 10, 0.005)
    rotvec = np.cumsum(rng.normal(0, 0.01, (len(t_gt), 3)), axis=0)
    rotvec = np.stack([np.convolve(rotvec[:, k], np.ones(20) / 20, mode="same") for k in range(3)], 1)
    R_gt = Rotation.from_rotvec(rotvec).as_matrix()
    gt = PoseSeries(t_gt, np.zeros((len(t_gt), 3)), quats_from_matrices(R_gt))
    t_frames = np.arange(0.5, 9.5, 0.05)
    true_offset = 0.0137
    from eas_vo.geometry import interpolate_poses

    _, R_true, _ = interpolate_poses(gt, t_frames + true_offset)
    noise = Rotation.from_rotvec(rng.normal(0, 0.0005, (len(t_frames), 3))).as_matrix()
    edges = [RelativeRotation(k - 1, k, R_true[k - 1].T @ R_true[k] @ noise[k]) for k in range(1, len(t_frames))]
    assert estimate_time_offset(t_frames, edges, gt) == pytest.approx(true_offset, abs=0.0005)


def test_auto_time_offset_on_the_real_excerpt(tmp_path):
    folder = str(require(SHAPES_ROTATION))
    out = tmp_path / "auto"
    assert main(["run", "--dataset", folder, "--frontend", "original", "--duration", "25", "--time-offset", "auto", "--out", str(out), "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    # The excerpt's README: frames lead ground truth by about 10 ms. Measured: +9.1 ms.
    assert metrics["time_offset_estimated"] and 0.005 < metrics["time_offset_s"] < 0.015


def test_lenient_flag_counts_and_reports(sequence_copy, tmp_path, capsys):
    path = sequence_copy / "events.txt"
    lines = path.read_bytes().split(b"\n")
    lines[100] = b"0.5 9999 3 1"  # out of the sensor
    lines[200] = b"garbage"
    path.write_bytes(b"\n".join(lines))
    assert main(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "strict"), "--quiet"]) == 2
    assert "events.txt:101: " in capsys.readouterr().err
    assert main(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "lenient"), "--quiet", "--lenient"]) == 0
    err = capsys.readouterr().err
    assert "eas-vo: warning:" in err and "1 dropped: malformed line (first at line 201)" in err
    assert "1 dropped: pixel outside the 240x180 sensor (first at line 101)" in err
    metrics = json.loads((tmp_path / "lenient" / "metrics.json").read_text())
    assert len(metrics["data_warnings"]) == 2
