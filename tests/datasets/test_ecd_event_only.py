"""Event Camera Dataset folders without frames: event-only streams sampled every N events."""

import numpy as np
import pytest

from eas_vo import config, pipeline
from eas_vo.cli import main
from eas_vo.datasets.ecd import EcdConfig, EcdFolderDataset
from helpers import EVENT_WINDOWS, require


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
