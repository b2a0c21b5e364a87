"""The Python API (eas_vo.api, exported by eas_vo): its results are the run's files, its frontends
the pipeline's, its scores `eas-vo evaluate`'s; and docs/python.md runs as written."""

import csv
import json

import numpy as np
import pytest

import eas_vo
from eas_vo import config as config_mod
from eas_vo.errors import ConfigError
from eas_vo.geometry.rotations import matrices_from_quats
from eas_vo.io.tum import read_tum
from eas_vo.pipeline import open_pipeline
from helpers import REPOSITORY, assert_rotations_close, code_blocks


@pytest.fixture(scope="module")
def api_run(short_sequence, tmp_path_factory):
    """The default run on the 2 s sequence, its files written."""
    return eas_vo.run(str(short_sequence), out=tmp_path_factory.mktemp("api") / "run")


def test_the_result_holds_what_the_run_wrote(api_run):
    result, folder = api_run, api_run.folder
    n = len(result.times)
    assert n > 10 and result.rotations.shape == (n, 3, 3) and result.ground_truth.shape == (n, 3, 3)
    trajectory = read_tum(folder / "trajectory.tum")
    np.testing.assert_allclose(trajectory.t, result.times, atol=1e-9)
    assert_rotations_close(matrices_from_quats(trajectory.q_w_c), result.rotations, 1e-9)
    scored = ~np.isnan(result.ape_rad)
    assert scored.any() and np.array_equal(scored, ~np.isnan(result.ground_truth).any(axis=(1, 2)))
    truth = read_tum(folder / "groundtruth.tum")
    np.testing.assert_allclose(truth.t, result.times[scored], atol=1e-9)
    assert_rotations_close(matrices_from_quats(truth.q_w_c), result.ground_truth[scored], 1e-9)
    assert json.loads((folder / "metrics.json").read_text()) == result.metrics
    assert result.ape_rad[scored].mean() == pytest.approx(result.metrics["ape_mean_rad"], rel=1e-12)
    assert (folder / "config.toml").read_text() == result.config.to_toml()


def test_the_frame_table_is_frames_csv(api_run):
    with open(api_run.folder / "frames.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    table = api_run.frames
    assert list(rows[0]) == list(table.dtype.names) and len(rows) == len(table) == len(api_run.times)
    np.testing.assert_array_equal(table.t, api_run.times)
    for name in table.dtype.names:
        written, held = [row[name] for row in rows], table[name]
        if held.dtype.kind == "U":
            assert written == held.tolist(), name
        elif held.dtype.kind == "b":
            assert written == [str(int(v)) for v in held], name
        else:
            as_read = np.array([float(v) if v else np.nan for v in written])
            np.testing.assert_allclose(as_read, held, rtol=0, atol=5e-5, err_msg=name)  # 4 decimals written
    assert np.isnan(table.sigma_deg[0]) and table.status[0] == "first"


def test_a_run_without_out_writes_nothing_and_takes_sets_as_section_keywords(short_sequence, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = eas_vo.run(str(short_sequence), tracker="klt", tracker__max_corners=np.int64(300), run__duration_s=0.5)
    assert result.folder is None and list(tmp_path.iterdir()) == []
    assert result.config.tracker.max_corners == 300 and result.config.run.duration_s == 0.5
    assert result.config.origin == "defaults --set tracker.max_corners=300 --set run.duration_s=0.5"
    assert result.times[-1] - result.times[0] < 0.5 and len(result.frames) == len(result.times)


def test_a_key_without_its_section_is_refused_before_any_work(short_sequence):
    with pytest.raises(ConfigError, match="tracker__max_corners"):
        eas_vo.run(str(short_sequence), max_corners=300)
    with pytest.raises(ConfigError, match="unknown key tracker.klt.max_cornerz"):
        eas_vo.run(str(short_sequence), tracker__max_cornerz=300)


@pytest.mark.parametrize("name, params", [("eas", {"n": 2000}), ("ts", {"tau_s": 0.02})])
def test_a_frontend_called_on_samples_gives_the_pipelines_images(short_sequence, name, params):
    assignments = [config_mod.assignment(f"frontend.{key}", value) for key, value in params.items()]
    pipeline_frontend = open_pipeline(
        config_mod.resolve(None, {"dataset": str(short_sequence), "frontend": name}, assignments)
    ).frontend
    dataset = eas_vo.open_dataset(str(short_sequence))
    frontend = eas_vo.frontend(name, dataset.camera, **params)
    assert frontend.config == pipeline_frontend.config
    for sample in dataset.samples(duration_s=0.5):
        image = frontend(sample)
        assert image.dtype == np.uint8 and image.shape == (dataset.camera.height, dataset.camera.width)
        np.testing.assert_array_equal(image, pipeline_frontend(sample))


def test_open_dataset_takes_its_plugins_settings(short_sequence):
    plain = eas_vo.open_dataset(str(short_sequence))
    shifted = eas_vo.open_dataset(str(short_sequence), ground_truth_time_offset_s=1.5)
    np.testing.assert_allclose(shifted.ground_truth.t, plain.ground_truth.t + 1.5)
    with pytest.raises(ConfigError, match="unknown key dataset.ecd.nope"):
        eas_vo.open_dataset(str(short_sequence), nope=1)
    with pytest.raises(ConfigError, match="unknown key frontend.eas.nope"):
        eas_vo.frontend("eas", plain.camera, nope=1)


def test_the_ground_truth_scored_against_itself_has_no_error(short_sequence):
    dataset = eas_vo.open_dataset(str(short_sequence))
    scores = eas_vo.evaluate(dataset.ground_truth, dataset)
    assert scores["matched_poses"] == len(dataset.ground_truth.t) and scores["estimate"] is None
    assert scores["ape_rot_rmse_rad"] == pytest.approx(0, abs=1e-9)
    assert scores["ape_trans_max_m"] == pytest.approx(0, abs=1e-9)


def test_evaluate_scores_a_run_in_memory_as_its_trajectory_file(api_run, short_sequence):
    spec = str(short_sequence)
    from_file = eas_vo.evaluate(api_run.folder / "trajectory.tum", spec)
    assert from_file["estimate"] == str(api_run.folder / "trajectory.tum")
    for estimate in (api_run, (api_run.times, api_run.rotations)):
        in_memory = eas_vo.evaluate(estimate, spec)
        assert in_memory.keys() == from_file.keys() and in_memory["estimate"] is None
        for key in from_file.keys() - {"estimate"}:  # the file's times have 9 decimals
            assert in_memory[key] == pytest.approx(from_file[key], abs=1e-9), key
    # The simulator's ground truth has a pose at each frame's time: evo's association then
    # scores the frames the run scored, and its origin alignment is Eq. 3's.
    assert from_file["ape_rot_mean_rad"] == pytest.approx(api_run.metrics["ape_mean_rad"], rel=1e-9)
    protocol = eas_vo.evaluate(api_run, spec, protocol="cmax-slam")
    assert protocol["protocol"] == "cmax-slam" and protocol["poses_scored"] == len(api_run.times)
    with pytest.raises(ConfigError, match="evo protocol's"):
        eas_vo.evaluate(api_run, spec, protocol="cmax-slam", align="origin")
    with pytest.raises(ConfigError, match="choose evo or cmax-slam"):
        eas_vo.evaluate(api_run, spec, protocol="evo_ape")


def test_the_python_page_runs(short_sequence, tmp_path, monkeypatch):
    """docs/python.md's python blocks, in order in one namespace, in an empty folder. The page
    runs on the embedded 10 s `synthetic:default`; here every "synthetic:default" in it is the
    session's 2 s simulated sequence instead (short_sequence), to keep the test short: it is the
    page's code that is tested, not its data."""
    page = (REPOSITORY / "docs" / "python.md").read_text()
    blocks = code_blocks(page, "python")
    assert len(blocks) >= 6 and all('"synthetic:default"' in b for b in (blocks[0], blocks[4]))
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for k, block in enumerate(blocks):
        code = block.replace('"synthetic:default"', repr(str(short_sequence)))
        exec(compile(code, f"docs/python.md, python block {k + 1}", "exec"), namespace)
    assert (tmp_path / "runs" / "fewer_corners" / "trajectory.tum").is_file()
