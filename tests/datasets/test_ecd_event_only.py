"""Event Camera Dataset folders without frames: event-only streams sampled every N events."""

import numpy as np
import pytest

from eas_vo import config, pipeline
from eas_vo.cli.main import main
from eas_vo.datasets.ecd import EcdConfig, EcdFolderDataset
from eas_vo.geometry.rotations import matrix_to_rotvec
from helpers import EVENT_WINDOWS, require


@pytest.mark.parametrize("name", ["boxes_rotation", "poster_rotation", "dynamic_rotation"])
def test_event_only_real_windows_run_the_slice_frontend(name):
    folder = require(EVENT_WINDOWS / name)
    ds = EcdFolderDataset(folder, EcdConfig(sample_every_events=3000))
    assert ds.load_frame(0) is None and len(ds.events()) == 30_000
    assert len(ds.frame_times()) == 10
    cfg = config.resolve(
        None, {"dataset": str(folder), "frontend": "slice"}, ["dataset.sample_every_events=3000", "frontend.n=3000"]
    )
    result = pipeline.run(cfg)
    assert result.metrics["frames"] == 10 and result.metrics["nc_mean"] > 50
    assert result.errors is None and np.isfinite(result.R_w_c).all()


def test_frame_frontend_on_an_event_only_stream_is_a_clear_error(capsys):
    folder = require(EVENT_WINDOWS / "boxes_rotation")
    assert main(["run", "--dataset", str(folder), "--frontend", "eas"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs APS frames" in err and "images.txt does not exist" in err


@pytest.mark.parametrize("name", ["boxes_rotation", "poster_rotation", "dynamic_rotation"])
def test_event_only_real_windows_run_cmax_without_a_frontend(name):
    """No frontend is chosen (the configured default, eas, needs frames): cmax runs with `no_image`.
    A sample every 7500 events, each interval's window its own 7500 (a window keeps to its
    interval): every window is ok, brings its events into sharper focus than no motion does
    (contrast gain over 1), and consecutive ones turn about similar axes."""
    folder = require(EVENT_WINDOWS / name)
    cfg = config.resolve(
        None,
        {"dataset": str(folder), "tracker": "cmax"},
        ["dataset.sample_every_events=7500", "tracker.window_events=7500"],
    )
    assert cfg.run.frontend == "no_image"
    result = pipeline.run(cfg)
    full = [r for r in result.records if r.events > 7000]
    assert len(full) >= 3 and all(r.status == "ok" and r.contrast_gain > 1.0 for r in full)
    steps = [matrix_to_rotvec(e.R_i_j) for e in result.edges if result.records[e.j].events > 7000]
    cosines = [a @ b / np.linalg.norm(a) / np.linalg.norm(b) for a, b in zip(steps, steps[1:])]
    assert min(cosines) > 0.8, np.round(cosines, 2)


def test_an_image_tracker_with_the_none_frontend_is_a_clear_error(capsys):
    folder = require(EVENT_WINDOWS / "boxes_rotation")
    assert main(["run", "--dataset", str(folder), "--frontend", "no_image", "--tracker", "klt"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "makes no images" in err
