"""A run folder as a Rerun recording (`eas-vo run --view`, `eas-vo view`), read back with
Rerun's own reader: every frame logged, the tracked points the run counted, the orientations,
curves and events; and the one-line errors (not a run folder, no rerun-sdk)."""

import csv
import subprocess
import sys
from collections import defaultdict

import pytest

from eas_vo.cli.main import main
from eas_vo.io.outputs import check_output_folder
from eas_vo.pipeline.view import MAX_EVENTS, NEEDED, RECORDING
from helpers import one_line_failure

NO_RERUN = "rerun-sdk is not installed (the `view` extra: pip install 'eas-vo[view]')"
EULER = [f"/euler/{angle}/{who}" for angle in ("roll", "pitch", "yaw") for who in ("estimate", "truth")]


@pytest.fixture(scope="module")
def viewed_run(short_sequence, tmp_path_factory):
    """The first 0.5 s (10 frames) of the short sequence run with --view: its folder."""
    pytest.importorskip("rerun", reason=NO_RERUN)
    out = tmp_path_factory.mktemp("view") / "run"
    argv = ["run", "--dataset", str(short_sequence), "--duration", "0.5", "--out", str(out), "--quiet", "--view"]
    assert main(argv) == 0
    return out


def recorded(path) -> dict[str, list[dict]]:
    """{entity path: its rows, each {column: value}} of the recording `path` (rerun.chunk.RrdReader);
    a static row has no `frame`."""
    from rerun.chunk import RrdReader

    rows = defaultdict(list)
    for chunk in RrdReader(path).stream():
        rows[chunk.entity_path] += chunk.to_record_batch().to_pylist()
    return rows


def per_frame(rows: list[dict], column: str) -> dict[int, object]:
    return {row["frame"]: row[column] for row in rows if "frame" in row}


def test_run_view_records_every_frame_its_points_orientations_curves_and_events(viewed_run):
    with open(viewed_run / "frames.csv", newline="") as fh:
        frames = list(csv.DictReader(fh))
    truth = [line for line in (viewed_run / "groundtruth.tum").read_text().splitlines() if line.strip()]
    rows = recorded(viewed_run / RECORDING)
    every_frame = ["/image", "/image/inliers", "/image/outliers", "/status", "/world/estimate", "/tracking/nc"]
    every_frame += ["/tracking/inliers", "/error/predicted_deg", *EULER[::2]]
    scored = ["/world/truth", "/error/ape_deg", *EULER[1::2]]
    counts = {entity: sum("frame" in row for row in rows[entity]) for entity in every_frame + scored}
    assert counts == {**dict.fromkeys(every_frame, len(frames)), **dict.fromkeys(scored, len(truth))}
    assert len(frames) == 10 and len(truth) > 0
    inliers = per_frame(rows["/image/inliers"], "Points2D:positions")
    outliers = per_frame(rows["/image/outliers"], "Points2D:positions")
    for frame in frames:  # the replay's points are the run's: as many as it tracked, its inliers among them
        k = int(frame["index"])
        assert len(inliers[k] or []) + len(outliers[k] or []) == int(frame["nc"])
        if frame["status"] in ("ok", "weak"):
            assert len(inliers[k]) == int(frame["inliers"]) > 0
    assert [row["TextLog:text"][0].split(":")[0] for row in rows["/status"]] == [f["status"] for f in frames]
    (events,) = rows["/events"]
    assert "frame" not in events and 0 < len(events["Points3D:positions"]) <= MAX_EVENTS
    check_output_folder(viewed_run, replace=True)  # run.rrd is listed as eas-vo's: --overwrite may replace the folder


def test_view_rewrites_the_recording_says_how_to_open_it_and_spawns_on_request(viewed_run, capsys, monkeypatch):
    opened = []
    monkeypatch.setattr(subprocess, "Popen", lambda argv, **kwargs: opened.append(argv))
    before = (viewed_run / RECORDING).stat().st_mtime_ns
    assert main(["view", str(viewed_run), "--spawn"]) == 0
    path = viewed_run.resolve() / RECORDING
    assert capsys.readouterr().out.splitlines() == [
        f"wrote {path} (10 frames): open it with `rerun {path}` or in https://app.rerun.io/version/"
        + sys.modules["rerun"].__version__
    ]
    assert (viewed_run / RECORDING).stat().st_mtime_ns != before
    assert opened == [[sys.executable, "-m", "rerun_cli", str(path)]]
    assert (viewed_run / ".eas-vo-output").read_text().splitlines().count(RECORDING) == 1


def test_a_folder_that_is_not_a_run_is_one_line(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("not a run\n")
    assert "is not a run folder: it holds no config.toml or frames.csv or trajectory.tum" in one_line_failure(
        ["view", str(tmp_path)], capsys
    )
    assert "is not a folder" in one_line_failure(["view", str(tmp_path / "notes.txt")], capsys)


def test_without_rerun_sdk_view_and_run_view_say_what_to_install(tmp_path, capsys, monkeypatch):
    """Before any work: the folder's files are not read, the run does not start."""
    for name in NEEDED:
        (tmp_path / name).write_text("")
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun raises ImportError
    said = 'eas-vo: error: the viewer needs rerun-sdk: pip install "eas-vo[view]"\n'
    assert one_line_failure(["view", str(tmp_path)], capsys) == said
    assert one_line_failure(["run", "--view", "--out", str(tmp_path / "run")], capsys) == said
    assert not (tmp_path / "run").exists()
