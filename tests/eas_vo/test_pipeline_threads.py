"""The concurrent run (a frame's two-view geometry on a worker thread while the next frame is
tracked, the alignment's scores split across the cores) gives what the serial path
(`--threads 1`) gives: the same trajectory, frames.csv and metrics, for every bundled config."""

from __future__ import annotations

import json

import pytest

from eas_vo import concurrency
from eas_vo.cli import main

#: metrics.json's keys that measure time, not results.
TIMINGS = {"elapsed_s", "load_s", "frames_per_s", "realtime_factor"}


@pytest.mark.parametrize("config", [None, "paper", "best"])
def test_threads_change_nothing_but_the_time(short_sequence, tmp_path, config):
    before = concurrency.threads()
    outputs = {}
    try:
        for threads in (1, 2):
            out = tmp_path / f"threads-{threads}"
            argv = ["run", "--dataset", str(short_sequence), "--threads", str(threads), "--out", str(out), "--quiet"]
            assert main(argv + (["--config", config] if config else [])) == 0
            metrics = json.loads((out / "metrics.json").read_text())
            outputs[threads] = ((out / "trajectory.tum").read_text(), (out / "frames.csv").read_text(),
                                {k: v for k, v in metrics.items() if k not in TIMINGS})
    finally:
        concurrency.set_threads(before)
    assert outputs[1][0] == outputs[2][0]
    assert outputs[1][1] == outputs[2][1]
    assert outputs[1][2] == outputs[2][2]
    assert outputs[1][2]["frames"] > 30
