"""The concurrent run (a frame's two-view geometry on a worker thread while the next frame is
tracked, the alignment's scores split across the cores) gives what the serial path
(`--threads 1`) gives: the same trajectory, frames.csv and metrics, for every bundled config
and every frontend, on a simulated sequence and on the real excerpt."""

from __future__ import annotations

import json

import pytest

from eas_vo import concurrency
from eas_vo.cli.main import main
from helpers import SHAPES_ROTATION, require

#: metrics.json's keys that measure time, not results.
TIMINGS = {"elapsed_s", "load_s", "frames_per_s", "realtime_factor"}


def outputs_by_threads(tmp_path, argv: list[str]) -> dict:
    """trajectory.tum, frames.csv and metrics.json less its timings, of `eas-vo run ARGV` with
    --threads 1 and 2."""
    before = concurrency.threads()
    outputs = {}
    try:
        for threads in (1, 2):
            out = tmp_path / f"threads-{threads}"
            assert main(["run", *argv, "--threads", str(threads), "--out", str(out), "--quiet"]) == 0
            metrics = json.loads((out / "metrics.json").read_text())
            outputs[threads] = (
                (out / "trajectory.tum").read_text(),
                (out / "frames.csv").read_text(),
                {k: v for k, v in metrics.items() if k not in TIMINGS},
            )
    finally:
        concurrency.set_threads(before)
    return outputs


@pytest.mark.parametrize(
    "config, frontend",
    [(None, None), ("paper", None), ("best", None)]
    + [(None, f) for f in ("original", "histeq", "slice", "ts", "sits")],
)
def test_threads_change_nothing_but_the_time(short_sequence, tmp_path, config, frontend):
    argv = (
        ["--dataset", str(short_sequence)]
        + (["--config", config] if config else [])
        + (["--frontend", frontend] if frontend else [])
    )
    outputs = outputs_by_threads(tmp_path, argv)
    assert outputs[1][0] == outputs[2][0]
    assert outputs[1][1] == outputs[2][1]
    assert outputs[1][2] == outputs[2][2]
    assert outputs[1][2]["frames"] > 30


@pytest.mark.parametrize("config", [None, "paper", "best"])
def test_threads_change_nothing_on_the_real_excerpt(tmp_path, config):
    """The real excerpt's fastest seconds (24-28 s, where best.toml's alignment fallback runs),
    through the histogram-equalised frames."""
    argv = ["--dataset", str(require(SHAPES_ROTATION)), "--frontend", "histeq", "--start", "24", "--duration", "4"]
    outputs = outputs_by_threads(tmp_path, argv + (["--config", config] if config else []))
    assert outputs[1] == outputs[2]
    assert outputs[1][2]["frames"] > 60
