"""`eas-vo info` and `eas-vo convert` as a user calls them: what they print, the output rules
they share with the other writing commands, and a run on a converted folder."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eas_vo.cli.main import main
from helpers import N_EVENTS, N_FRAMES, known_sequence, one_line_failure


def test_info_prints_each_stream(tmp_path, capsys):
    folder = known_sequence(tmp_path / "seq")
    assert main(["info", "--dataset", str(folder)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{folder} (dataset plugin ecd)\n")
    for says in (
        "streams       frames, events, IMU, ground truth",
        "sensor        346 x 260 px",
        f"frames        {N_FRAMES} APS frames, 0.500-0.940 s (0.440 s), 25 Hz",
        "IMU           150 readings, 0.420-1.016 s (0.596 s), 250 Hz",
        "ground truth  100 poses, 0.450-0.945 s (0.495 s), 200 Hz",
        f"events        {N_EVENTS} events, ",
    ):
        assert says in out, (says, out)


def test_info_of_a_missing_dataset_is_one_line(tmp_path, capsys):
    assert "dataset not found" in one_line_failure(["info", "--dataset", str(tmp_path / "nowhere")], capsys)


def test_a_run_on_a_converted_sequence_gives_the_same_trajectory(short_sequence, tmp_path, capsys):
    converted = tmp_path / "converted"
    assert main(["convert", "--dataset", str(short_sequence), "--out", str(converted), "--quiet"]) == 0
    assert f"as an Event Camera Dataset folder to {converted}" in capsys.readouterr().out
    trajectories = []
    for name, folder in (("original", short_sequence), ("converted", converted)):
        assert (
            main(
                [
                    "run",
                    "--dataset",
                    str(folder),
                    "--config",
                    "paper",
                    "--out",
                    str(tmp_path / f"run_{name}"),
                    "--quiet",
                ]
            )
            == 0
        )
        trajectories.append(np.loadtxt(tmp_path / f"run_{name}" / "trajectory.tum"))
    assert trajectories[0].shape == trajectories[1].shape and len(trajectories[0]) > 10
    np.testing.assert_allclose(trajectories[1], trajectories[0], rtol=0, atol=1e-6)
    metrics = [
        json.loads((tmp_path / f"run_{name}" / "metrics.json").read_text()) for name in ("original", "converted")
    ]
    assert metrics[1]["ape_mean_rad"] == pytest.approx(metrics[0]["ape_mean_rad"], abs=1e-9)


def test_convert_follows_the_output_rules_of_every_writing_command(tmp_path, capsys):
    folder = known_sequence(tmp_path / "seq")
    out = tmp_path / "out"
    assert main(["convert", "--dataset", str(folder), "--out", str(out), "--duration", "0.2"]) == 0
    first = (out / "images.txt").read_text()
    assert "is not empty; choose another folder or add --overwrite" in one_line_failure(
        ["convert", "--dataset", str(folder), "--out", str(out)], capsys
    )
    assert main(["convert", "--dataset", str(folder), "--out", str(out), "--overwrite"]) == 0  # its own output
    assert len((out / "images.txt").read_text().splitlines()) == N_FRAMES > len(first.splitlines())
    (out / "notes.txt").write_text("mine")
    assert "which eas-vo did not write" in one_line_failure(
        ["convert", "--dataset", str(folder), "--out", str(out), "--overwrite"], capsys
    )
    (out / "notes.txt").unlink()
    assert "holds the dataset" in one_line_failure(  # a converted folder is a dataset too: never replaced by itself
        ["convert", "--dataset", str(out), "--out", str(out), "--overwrite"], capsys
    )
    assert "holds no sample" in one_line_failure(
        ["convert", "--dataset", str(folder), "--out", str(tmp_path / "late"), "--start", "5"], capsys
    )
    assert not (tmp_path / "late").exists()


def test_convert_of_an_event_only_stream_says_how_to_open_it(tmp_path, capsys):
    folder = known_sequence(tmp_path / "seq", frames=False)
    sensor = ["--set", "dataset.width=346", "--set", "dataset.height=260"]
    assert main(["convert", "--dataset", str(folder), *sensor, "--out", str(tmp_path / "out")]) == 0
    assert "open it with --set dataset.width=346 --set dataset.height=260" in capsys.readouterr().out
    assert main(["info", "--dataset", str(tmp_path / "out"), *sensor]) == 0
    assert f"events        {N_EVENTS} events" in capsys.readouterr().out
