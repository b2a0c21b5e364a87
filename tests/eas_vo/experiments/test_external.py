"""The ORB-SLAM2 path: exported sequences read back, settings.yaml as ORB-SLAM2 reads it, and
external trajectories scored exactly as evo_ape does."""

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.errors import DataError
from eas_vo.evaluation.trajectory import associate, trajectory_ape
from eas_vo.geometry.rotations import matrices_from_quats
from eas_vo.io.tum import format_tum
from eas_vo.io.tum import read_tum as read_estimate
from eas_vo.types import PoseSeries
from helpers import mark_as_eas_vo_output, run_eas_vo


def _frontend_pixels(sequence, frames, frontend):
    from eas_vo.experiments.gallery import frontend_images

    _, images = frontend_images(str(sequence), frames, [frontend])
    return {k: images[(k, frontend)] for k in frames}


@pytest.mark.parametrize("fmt", ["tum", "euroc"])
def test_an_exported_sequence_reads_back_as_the_frontends_images(short_sequence, tmp_path, fmt):
    out = tmp_path / fmt
    done = run_eas_vo(
        "export",
        "--dataset",
        str(short_sequence),
        "--frontend",
        "eas",
        "--format",
        fmt,
        "--duration",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert done.returncode == 0, done.stderr
    if fmt == "tum":
        lines = (out / "rgb.txt").read_text().splitlines()
        assert all(line.startswith("#") for line in lines[:3])  # mono_tum skips three lines
        listed = [(float(t), out / name) for t, name in (line.split() for line in lines[3:])]
    else:
        stamps = (out / "timestamps.txt").read_text().split()
        csv = (out / "mav0/cam0/data.csv").read_text().splitlines()[1:]
        assert [row.split(",")[0] for row in csv] == stamps
        listed = [(int(ns) * 1e-9, out / "mav0/cam0/data" / f"{ns}.png") for ns in stamps]
    times = np.loadtxt(short_sequence / "images.txt", usecols=0)
    assert len(listed) == np.count_nonzero(times < times[0] + 1)
    np.testing.assert_allclose([t for t, _ in listed], times[: len(listed)], atol=1e-6)
    pixels = _frontend_pixels(short_sequence, [0, 7, len(listed) - 1], "eas")
    for k, (_, path) in enumerate(listed):
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        assert image is not None and image.dtype == np.uint8 and image.shape == (180, 240), path
        if k in pixels:
            np.testing.assert_array_equal(image, pixels[k])


def test_settings_yaml_holds_the_calibration_as_orbslam2_reads_it(short_sequence, tmp_path):
    out = tmp_path / "tum"
    assert (
        run_eas_vo(
            "export", "--dataset", str(short_sequence), "--frontend", "original", "--out", str(out), "--quiet"
        ).returncode
        == 0
    )
    fs = cv2.FileStorage(str(out / "settings.yaml"), cv2.FILE_STORAGE_READ)  # ORB-SLAM2's own reader
    calib = np.loadtxt(short_sequence / "calib.txt")
    keys = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
    np.testing.assert_allclose([fs.getNode(f"Camera.{k}").real() for k in keys], calib[: len(keys)], rtol=1e-12)
    times = np.loadtxt(short_sequence / "images.txt", usecols=0)
    assert fs.getNode("Camera.fps").real() == pytest.approx((len(times) - 1) / (times[-1] - times[0]))
    assert fs.getNode("ORBextractor.nFeatures").real() == 1000 and fs.getNode("ORBextractor.nLevels").real() == 8
    assert fs.getNode("Camera.width").real() == 240 and fs.getNode("Camera.height").real() == 180


def _ground_truth(n=400, seed=0) -> PoseSeries:
    """A hand-held-like 6-DoF path: 20 s at 20 Hz, metres of motion, tens of degrees of turn."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.05
    p = np.cumsum(rng.normal(0, 0.03, (n, 3)), axis=0) + np.c_[np.sin(t), np.cos(0.7 * t), 0.3 * t]
    q = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)).as_quat()
    return PoseSeries(t, p, q)


def _similar(gt: PoseSeries, R_a, t_a, s, seed=1, every=3):
    """The ground truth seen by a monocular SLAM: every 3rd pose, times jittered by up to
    3 ms, mapped by x -> s R_a x + t_a, with position and rotation noise."""
    rng = np.random.default_rng(seed)
    idx = np.arange(0, len(gt.t), every)
    t = gt.t[idx] + rng.uniform(-0.003, 0.003, len(idx))
    p = s * gt.p_w_c[idx] @ R_a.T + t_a + rng.normal(0, 0.002, (len(idx), 3))
    R = R_a @ matrices_from_quats(gt.q_w_c[idx]) @ Rotation.from_rotvec(rng.normal(0, 0.002, (len(idx), 3))).as_matrix()
    return PoseSeries(t, p, Rotation.from_matrix(R).as_quat())


def test_sim3_alignment_recovers_a_known_similarity():
    gt = _ground_truth()
    R_a, t_a, s = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix(), np.array([1.0, 2.0, -0.5]), 0.37
    ape = trajectory_ape(gt, _similar(gt, R_a, t_a, s), "sim3")
    assert ape.scale == pytest.approx(1 / s, rel=2e-3)  # the estimate is mapped back onto the ground truth
    assert np.degrees(Rotation.from_matrix(ape.R_align @ R_a).magnitude()) < 0.05
    np.testing.assert_allclose(ape.t_align, -(1 / s) * R_a.T @ t_a, atol=5e-3)
    summary = ape.summary()
    assert (
        summary["matched_poses"] == 134 and summary["ape_trans_mean_m"] < 0.01 and summary["ape_rot_mean_rad"] < 0.005
    )


def _evo_ape(gt_path, est_path, align, relation):
    from evo.core import metrics, sync
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(gt_path))
    est = file_interface.read_tum_trajectory_file(str(est_path))
    ref, est = sync.associate_trajectories(ref, est, max_diff=0.01)
    if align == "origin":
        est.align_origin(ref)
    else:
        est.align(ref, correct_scale=align == "sim3")
    ape = metrics.APE(relation)
    ape.process_data((ref, est))
    return ape.get_statistic(metrics.StatisticsType.mean), ape.get_statistic(metrics.StatisticsType.rmse)


@pytest.mark.parametrize("align", ["sim3", "se3", "origin"])
def test_evaluate_equals_evo_ape_on_the_same_files(short_sequence, tmp_path, align):
    from evo.core.metrics import PoseRelation

    from eas_vo.registry import open_dataset

    gt = open_dataset(str(short_sequence)).ground_truth
    est = _similar(gt, Rotation.from_rotvec([0.1, 0.4, -0.2]).as_matrix(), np.array([0.2, -1.0, 0.4]), 2.5, every=7)
    est_path = tmp_path / "KeyFrameTrajectory.txt"
    est_path.write_text(format_tum(est.t, est.p_w_c, matrices_from_quats(est.q_w_c)))
    out = tmp_path / "eval"
    done = run_eas_vo(
        "evaluate", "--dataset", str(short_sequence), "--estimate", str(est_path), "--align", align, "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    ours = json.loads((out / "metrics.json").read_text())
    trans = _evo_ape(out / "groundtruth.tum", est_path, align, PoseRelation.translation_part)
    rot = _evo_ape(out / "groundtruth.tum", est_path, align, PoseRelation.rotation_angle_rad)
    assert ours["ape_trans_mean_m"] == pytest.approx(trans[0], abs=1e-6)
    assert ours["ape_trans_rmse_m"] == pytest.approx(trans[1], abs=1e-6)
    assert ours["ape_rot_mean_rad"] == pytest.approx(rot[0], abs=1e-6)
    assert "| KeyFrameTrajectory |" in (out / "table2_row.md").read_text()


def test_evaluate_equals_the_evo_ape_command(short_sequence, tmp_path):
    """The peer as a user runs it: `evo_ape tum GT EST -as` prints the same mean."""
    from eas_vo.registry import open_dataset

    gt = open_dataset(str(short_sequence)).ground_truth
    est = _similar(gt, np.eye(3), np.zeros(3), 0.8, every=5)
    est_path = tmp_path / "est.tum"
    est_path.write_text(format_tum(est.t, est.p_w_c, matrices_from_quats(est.q_w_c)))
    out = tmp_path / "eval"
    assert (
        run_eas_vo(
            "evaluate", "--dataset", str(short_sequence), "--estimate", str(est_path), "--out", str(out)
        ).returncode
        == 0
    )
    evo_ape = Path(sys.executable).with_name("evo_ape")
    if not evo_ape.exists():
        pytest.skip("evo_ape is not installed beside this Python")
    printed = subprocess.run(
        [str(evo_ape), "tum", str(out / "groundtruth.tum"), str(est_path), "-as"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    ).stdout
    mean = float(next(line.split()[1] for line in printed.splitlines() if line.strip().startswith("mean")))
    assert json.loads((out / "metrics.json").read_text())["ape_trans_mean_m"] == pytest.approx(mean, abs=1e-6)


def test_association_equals_evos():
    from evo.core.sync import matching_time_indices

    rng = np.random.default_rng(4)
    for _ in range(50):
        a = np.sort(rng.uniform(0, 5, rng.integers(1, 60)))
        b = np.sort(rng.choice(np.round(rng.uniform(0, 5, 80), 2), rng.integers(1, 80), replace=False))
        i_a, i_b = associate(a, b, 0.02)
        short, long_ = (a, b) if len(a) < len(b) else (b, a)
        i_short, i_long = matching_time_indices(short, long_, 0.02)
        expected = (i_short, i_long) if len(a) < len(b) else (i_long, i_short)
        assert list(i_a) == list(expected[0]) and list(i_b) == list(expected[1])


@pytest.mark.parametrize(
    "text, line, message",
    [
        ("1 0 0 0 0 0 0 1\n# c\n1 0 0 0 0 0 0 1\n", 3, "timestamp 1.000000000 repeats the previous row's"),
        ("1 0 0 0 0 0 0 1\n\n2 0 0 0 0 0 0 0\n", 3, "quaternion norm 0.000 is not 1"),
        ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", 2, "expected 8 columns"),
    ],
)
def test_a_bad_estimate_file_names_its_line(tmp_path, text, line, message):
    path = tmp_path / "est.txt"
    path.write_text(text)
    with pytest.raises(DataError, match=f"est.txt:{line}.*{message}"):
        read_estimate(path)


def test_evaluate_never_writes_over_its_dataset_or_its_estimate(short_sequence, tmp_path):
    """An --out holding the dataset or the --estimate is refused (with --overwrite too), both kept."""
    import shutil

    dataset = tmp_path / "seq"
    shutil.copytree(short_sequence, dataset)
    estimate = tmp_path / "slam" / "KeyFrameTrajectory.txt"
    estimate.parent.mkdir()
    gt = np.loadtxt(dataset / "groundtruth.txt")[::10]
    estimate.write_text("".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in gt))
    for out, says in ((dataset, "holds the dataset"), (estimate.parent, "holds the --estimate")):
        mark_as_eas_vo_output(out)  # as if eas-vo wrote all of it
        done = run_eas_vo(
            "evaluate", "--dataset", str(dataset), "--estimate", str(estimate), "--out", str(out), "--overwrite"
        )
        assert done.returncode == 1 and says in done.stderr and done.stderr.count("\n") == 1, done.stderr
    assert (dataset / "events.txt").exists() and estimate.exists()


@pytest.mark.parametrize("fmt", ["tum", "euroc"])
def test_frames_that_would_share_an_image_name_are_refused_before_any_work(short_sequence, tmp_path, fmt):
    """TUM names an image by its time in us, EuRoC in ns: two frames at one such time are named
    (one image written over the other before); frames 0.3 us apart share a TUM name only."""
    from eas_vo.config import resolve
    from eas_vo.errors import EasVoError
    from eas_vo.slam.export import export

    sequence = tmp_path / "seq"  # the short sequence's files (its event cache too), with other frame times
    sequence.mkdir()
    for name in ("events.txt", "calib.txt", "groundtruth.txt", "images"):
        (sequence / name).symlink_to(short_sequence / name)
    lines = (short_sequence / "images.txt").read_text().splitlines()
    t20 = float(lines[20].split()[0])
    lines[21] = f"{t20 + 3e-7:.9f} {lines[21].split()[1]}"
    (sequence / "images.txt").write_text("\n".join(lines) + "\n")
    config = resolve(None, {"dataset": str(sequence), "frontend": "original"})
    if fmt == "tum":
        with pytest.raises(EasVoError, match=rf"frames 20 and 21 have one timestamp in the tum layout \({t20:.6f}\)"):
            export(config, tmp_path / "tum", fmt)
    else:  # distinct to the ns: every frame its own image, as many as said
        done = export(config, tmp_path / "euroc", fmt)
        assert done["frames"] == len(lines) == len(list((tmp_path / "euroc/mav0/cam0/data").iterdir()))
    lines[10] = f"{lines[9].split()[0]} {lines[10].split()[1]}"
    (sequence / "images.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(EasVoError, match=rf"frames 9 and 10 have one timestamp in the {fmt} layout"):
        export(resolve(None, {"dataset": str(sequence), "frontend": "original"}), tmp_path / "again", fmt)
    assert not (tmp_path / "tum").exists() and not (tmp_path / "again").exists()


def test_a_label_never_breaks_the_table_row():
    """A `|`, a newline or a control character in --label: one row of six cells, the `|` escaped."""
    from eas_vo.experiments.external import table2_row

    metrics = {
        "ape_trans_mean_m": 0.02,
        "ape_trans_rmse_m": 0.03,
        "ape_rot_mean_rad": 0.1,
        "scale": 1.5,
        "matched_poses": 9,
    }
    header, rule, row = table2_row("eas | v2\nsecond\tline\x1b", metrics).splitlines()
    assert row == "| eas \\| v2 second line | 0.020 | 0.030 | 0.100 | 1.5 | 9 |"
    assert row.replace("\\|", "").count("|") == header.count("|") == 7


def test_a_huge_error_is_printed_readably(short_sequence, tmp_path, capsys):
    """Positions of 1e150 m: the CLI line and the table row give the APE in scientific notation
    (no 150-digit number), each the metrics.json value to the digits shown."""
    import re

    from eas_vo.cli.main import main

    gt = np.loadtxt(short_sequence / "groundtruth.txt")[::10]
    gt[:, 1:4] = gt[:, 1:4] * 1e150 + 1e150
    estimate = tmp_path / "huge.tum"
    estimate.write_text("".join(" ".join(f"{v:.17g}" for v in row) + "\n" for row in gt))
    out = tmp_path / "ev"
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                str(short_sequence),
                "--estimate",
                str(estimate),
                "--align",
                "se3",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    said = capsys.readouterr().out
    row = (out / "table2_row.md").read_text().splitlines()[2]
    mean = json.loads((out / "metrics.json").read_text())["ape_trans_mean_m"]
    assert mean > 1e100
    for text, digits in ((said, 4), (row, 3)):
        assert re.search(r"\d{10}", text) is None, text
        shown = [float(v) for v in re.findall(r"\d\.\d+e\+\d+", text)]
        assert shown and shown[0] == pytest.approx(mean, rel=10.0**-digits), text


@pytest.mark.parametrize(
    "model, dist, camera_type",
    [
        ("radtan", [-0.3, 0.1, 0.001, -0.002, 0.01], "PinHole"),
        ("equidistant", [-0.048, 0.0113, -0.0554, 0.0215], "KannalaBrandt8"),
    ],
)
def test_settings_yaml_names_the_lens_as_orbslam3_reads_it(tmp_path, model, dist, camera_type):
    from eas_vo.camera import LENS_MODELS, CameraModel
    from eas_vo.slam.export import settings_yaml

    K = np.array([[226.4, 0.0, 173.6], [0.0, 226.2, 133.7], [0.0, 0.0, 1.0]])
    (tmp_path / "settings.yaml").write_text(settings_yaml(CameraModel(346, 260, K, np.array(dist), model), 20.0))
    fs = cv2.FileStorage(str(tmp_path / "settings.yaml"), cv2.FILE_STORAGE_READ)
    assert fs.getNode("Camera.type").string() == camera_type  # ORB-SLAM3's Tracking::ParseCamParamFile switches on it
    names = LENS_MODELS[model]
    assert [fs.getNode(f"Camera.{k}").real() for k in names] == dist
    assert all(fs.getNode(f"Camera.{k}").empty() for k in {"p1", "p2", "k3", "k4"} - set(names))
    assert (fs.getNode("Camera.width").real(), fs.getNode("Camera.height").real()) == (346, 260)


@pytest.mark.parametrize("shift_s", [0, 1_700_000_000], ids=["zero", "unix"])
def test_evaluate_reads_an_estimate_on_the_recordings_own_clock(tmp_path, capsys, shift_s):
    """An estimate holds the recording's own times (a run's trajectory.tum adds the clock origin
    back): its own ground truth scores it exactly, and the files written keep those times."""
    from eas_vo.cli.main import main
    from helpers import sequence_with

    folder = sequence_with(tmp_path / "seq", None, 1, shift_s)
    out = tmp_path / "ev"
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                str(folder),
                "--estimate",
                str(folder / "groundtruth.txt"),
                "--align",
                "origin",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["matched_poses"], metrics["matched_fraction"], metrics["warnings"]) == (100, 1.0, [])
    assert metrics["ape_rot_mean_rad"] < 1e-9 and metrics["ground_truth_span_s"] == [0.0, pytest.approx(0.495)]
    np.testing.assert_array_equal(
        np.loadtxt(out / "groundtruth.tum")[:, 0], np.loadtxt(folder / "groundtruth.txt")[:, 0]
    )


def test_evaluate_refuses_an_estimate_in_microseconds_and_warns_on_a_partial_ground_truth(tmp_path, capsys):
    from eas_vo.cli.main import main
    from helpers import one_line_failure, retimed, sequence_with

    folder = sequence_with(tmp_path / "seq", None, 1)
    micro = tmp_path / "micro.tum"
    micro.write_text((folder / "groundtruth.txt").read_text())
    retimed(micro, 10**6)
    err = one_line_failure(["evaluate", "--dataset", str(folder), "--estimate", str(micro)], capsys)
    assert f"{micro}: the estimate timestamps span" in err and "look like microseconds" in err, err
    estimate = tmp_path / "all.tum"
    estimate.write_text((folder / "groundtruth.txt").read_text())
    rows = (folder / "groundtruth.txt").read_text().splitlines()
    (folder / "groundtruth.txt").write_text("\n".join(rows[50:]) + "\n")  # the second half of the poses
    assert main(["evaluate", "--dataset", str(folder), "--estimate", str(estimate), "--align", "origin"]) == 0
    said = capsys.readouterr()
    assert "warning: the ground truth scores only 50 of the estimate's 100 poses (50 %, under 90 %)" in said.err
    assert "50 of 100 poses matched" in said.out
