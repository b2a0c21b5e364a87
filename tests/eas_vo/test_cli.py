"""The real CLI, in-process and as a subprocess: outputs, evo agreement, user errors."""

import csv
import json
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from eas_vo.cli.main import main
from helpers import one_line_failure, run_eas_vo

OUTPUTS = (
    "trajectory.tum",
    "groundtruth.tum",
    "orientation_sigma.csv",
    "metrics.json",
    "frames.csv",
    "config.toml",
    "rotation.png",
)


@pytest.fixture(scope="module")
def eas_run(short_sequence, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "eas"
    assert main(["run", "--dataset", str(short_sequence), "--frontend", "eas", "--out", str(out), "--quiet"]) == 0
    return out


def test_run_writes_every_output(eas_run):
    for name in OUTPUTS:
        assert (eas_run / name).stat().st_size > 0, name
    metrics = json.loads((eas_run / "metrics.json").read_text())
    for key in (
        "ape_mean_rad",
        "ape_rmse_rad",
        "ape_max_rad",
        "nc_mean",
        "frames",
        "frontend",
        "backend",
        "dataset",
        "elapsed_s",
    ):
        assert key in metrics, key
    assert metrics["frontend"] == "eas" and metrics["backend"] == "chain"
    rows = list(csv.DictReader(open(eas_run / "frames.csv")))
    assert len(rows) == metrics["frames"] == len((eas_run / "trajectory.tum").read_text().splitlines())
    assert metrics["nc_mean"] == pytest.approx(np.mean([int(r["nc"]) for r in rows[1:]]))
    assert metrics["edge_count"] == sum(r["status"] in ("ok", "weak") for r in rows) and metrics["loop_count"] is None
    assert (eas_run / "rotation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cache_lists_clears_and_a_run_rebuilds_what_was_cleared(short_sequence, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(tmp_path / "cache"))
    first = tmp_path / "first"
    assert main(["run", "--dataset", str(short_sequence), "--out", str(first), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["cache"]) == 0
    listed = capsys.readouterr().out
    assert re.search(r"events +1 entries +[0-9.]+ MB +binary event caches", listed), listed
    assert main(["cache", "--clear", "events", "--clear", "nothing_here"]) == 1  # every name checked first
    assert (
        "cache 'nothing_here': not in" in capsys.readouterr().err
        and len(list((tmp_path / "cache" / "events").glob("*.ev"))) == 1
    )
    assert main(["cache", "--clear", "events"]) == 0
    assert re.fullmatch(r"events: cleared, [0-9.]+ MB freed\n", capsys.readouterr().out)
    assert list((tmp_path / "cache" / "events").glob("*.ev")) == []
    again = tmp_path / "again"
    assert main(["run", "--dataset", str(short_sequence), "--out", str(again), "--quiet"]) == 0
    assert len(list((tmp_path / "cache" / "events").glob("*.ev"))) == 1
    assert (
        json.loads((again / "metrics.json").read_text())["ape_mean_rad"]
        == json.loads((first / "metrics.json").read_text())["ape_mean_rad"]
    )


def test_a_run_with_loop_closure_says_how_many_loops_closed(short_sequence, tmp_path, capsys):
    out = tmp_path / "loops"
    assert (
        main(
            [
                "run",
                "--dataset",
                str(short_sequence),
                "--frontend",
                "eas",
                "--set",
                "tracker.loop_closure=true",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    loops = json.loads((out / "metrics.json").read_text())["loop_count"]
    assert f", {loops} loop(s) closed, " in capsys.readouterr().out


def test_evo_reports_the_same_average_ape(eas_run):
    beside = Path(sys.executable).parent / "evo_ape"  # the evo of this interpreter, venv or not
    evo_ape = str(beside) if beside.exists() else shutil.which("evo_ape")
    if evo_ape is None:
        pytest.skip("evo_ape not found beside the Python interpreter nor on PATH")
    result = subprocess.run(
        [
            evo_ape,
            "tum",
            str(eas_run / "groundtruth.tum"),
            str(eas_run / "trajectory.tum"),
            "-r",
            "angle_rad",
            "--align_origin",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    evo_mean = float(re.search(r"^\s*mean\s+([0-9.eE+-]+)", result.stdout, re.M).group(1))
    ours = json.loads((eas_run / "metrics.json").read_text())["ape_mean_rad"]
    assert evo_mean == pytest.approx(ours, abs=1e-6)


def test_resolved_config_reproduces_the_run(eas_run, tmp_path):
    out = tmp_path / "again"
    assert main(["run", "--config", str(eas_run / "config.toml"), "--out", str(out), "--quiet"]) == 0
    first = json.loads((eas_run / "metrics.json").read_text())
    second = json.loads((out / "metrics.json").read_text())
    assert second["ape_mean_rad"] == first["ape_mean_rad"] and second["nc_mean"] == first["nc_mean"]


def test_start_and_duration_select_the_window(short_sequence, tmp_path):
    out = tmp_path / "w"
    assert (
        main(
            [
                "run",
                "--dataset",
                str(short_sequence),
                "--frontend",
                "original",
                "--start",
                "0.5",
                "--duration",
                "0.5",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    assert json.loads((out / "metrics.json").read_text())["frames"] == 10


def user_error(argv, capsys, usage: bool = False):
    """The one line of a failed command, which exits with 1 (2 for a `usage` error)."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == (2 if usage else 1)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_missing_images_txt_is_one_line(sequence_copy, tmp_path, capsys):
    (sequence_copy / "images.txt").unlink()
    line = user_error(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "o")], capsys)
    assert line.startswith("eas-vo: error: ") and "needs APS frames" in line and "images.txt does not exist" in line


def test_bad_event_line_is_one_line_with_file_and_line(sequence_copy, tmp_path, capsys):
    path = sequence_copy / "events.txt"
    with open(path, "r+b") as fh:
        head = b"".join(fh.readline() for _ in range(4))
        fh.seek(len(head))
        fh.write(b"0.0 garbage")
    line = user_error(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "o")], capsys)
    assert re.search(r"events.txt:5: ", line), line


def test_missing_frame_file_is_one_line(sequence_copy, tmp_path, capsys):
    (sequence_copy / "images" / "frame_00000007.png").unlink()
    line = user_error(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "o")], capsys)
    assert "images.txt:8: frame file images/frame_00000007.png does not exist" in line


def test_unknown_plugin_and_bad_config_are_one_line(short_sequence, tmp_path, capsys):
    line = user_error(["run", "--dataset", str(short_sequence), "--frontend", "nope"], capsys)
    assert "unknown frontend 'nope'; installed:" in line
    line = user_error(["run", "--dataset", str(short_sequence), "--set", "frontend.beta=999"], capsys)
    assert "beta" in line


def test_subprocess_entry_point_help_and_error():
    help_text = run_eas_vo("run", "--help")
    assert help_text.returncode == 0 and "metrics.json" in help_text.stdout
    bad = run_eas_vo("run", "--dataset", "/nonexistent/folder")
    assert bad.returncode == 1 and bad.stderr.count("\n") == 1 and "dataset not found" in bad.stderr


def test_run_help_lists_the_installed_plugins_of_every_kind(monkeypatch, capsys):
    """From the registry's entry points, a third party's too: no hand-kept list."""
    from eas_vo import registry

    real = registry.names
    monkeypatch.setattr(registry, "names", lambda kind: real(kind) + [f"thirdparty_{kind}"])
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    shown = " ".join(capsys.readouterr().out.split())
    for option, kind in (
        ("--dataset", "datasets"),
        ("--frontend", "frontends"),
        ("--tracker", "trackers"),
        ("--backend", "backends"),
    ):
        assert re.search(
            rf"{option} \S+ (?:(?! --[a-z]).)*one of {', '.join(real(kind))}, thirdparty_{kind}\b", shown
        ), (option, shown)


def test_simulate_command(tmp_path, capsys):
    """A sequence is written; with --speed 3 the camera turns three times as far in the ground
    truth's first 5 ms (the same path, faster: test_motion has the exact relation)."""
    from scipy.spatial.transform import Rotation

    turned = {}
    for speed in ("1", "3"):
        out = tmp_path / speed
        assert main(["simulate", "--out", str(out), "--seed", "2", "--duration", "0.4", "--speed", speed]) == 0
        assert (out / "images.txt").exists()
        assert (
            f"wrote a 0.4 s synthetic sequence (seed 2, illumination 1, speed {speed}, 240x180 radtan)"
            in capsys.readouterr().out
        )
        q = Rotation.from_quat(np.loadtxt(out / "groundtruth.txt")[:2, 4:8])
        turned[speed] = (q[0].inv() * q[1]).magnitude()
    assert turned["3"] / turned["1"] == pytest.approx(3.0, rel=0.02), turned
    assert (
        main(
            [
                "simulate",
                "--out",
                str(tmp_path / "set"),
                "--duration",
                "0.3",
                "--set",
                "dataset.speed=2",
                "--set",
                "dataset.illumination=0.5",
                "--set",
                "dataset.sensor=davis346",
            ]
        )
        == 0
    )
    assert "(seed 0, illumination 0.5, speed 2, 346x260 equidistant)" in capsys.readouterr().out
    assert (tmp_path / "set" / "camchain.yaml").exists() and not (tmp_path / "set" / "calib.txt").exists()
    line = user_error(
        ["simulate", "--out", str(tmp_path / "both"), "--speed", "2", "--set", "dataset.speed=3"], capsys, usage=True
    )
    assert line == "eas-vo: error: --speed and --set dataset.speed both given: give one"


def stats_of(capsys, tmp_path, illumination):
    """`eas-vo simulate --stats` output -> (events/s, noise fraction, dark latency [ms])."""
    import re

    assert (
        main(
            [
                "simulate",
                "--out",
                str(tmp_path / str(illumination)),
                "--duration",
                "1.0",
                "--illumination",
                str(illumination),
                "--stats",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    rate = float(re.search(r"\(([\d.]+) M events/s\)", text).group(1))
    noise = float(re.search(r"noise fraction ([\d.]+)", text).group(1))
    latency = float(re.search(r"crossing: dark ([\d.]+) ms", text).group(1))
    assert "noise rate per pixel: dark" in text
    return rate, noise, latency


def test_simulate_stats_darker_means_fewer_later_noisier_events(tmp_path, capsys):
    bright, dark = stats_of(capsys, tmp_path, 1.0), stats_of(capsys, tmp_path, 0.1)
    assert dark[0] < bright[0] and dark[1] > bright[1] and dark[2] > bright[2], (bright, dark)


def test_lenient_flag_counts_and_reports(sequence_copy, tmp_path, capsys):
    path = sequence_copy / "events.txt"
    lines = path.read_bytes().split(b"\n")
    lines[100] = b"0.5 9999 3 1"  # out of the sensor
    lines[200] = b"garbage"
    path.write_bytes(b"\n".join(lines))
    assert main(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "strict"), "--quiet"]) == 1
    assert "events.txt:101: " in capsys.readouterr().err
    assert (
        main(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "lenient"), "--quiet", "--lenient"]) == 0
    )
    err = capsys.readouterr().err
    assert "eas-vo: warning:" in err and "1 dropped: malformed line (first at line 201)" in err
    assert "1 dropped: pixel outside the 240x180 sensor (first at line 101)" in err
    metrics = json.loads((tmp_path / "lenient" / "metrics.json").read_text())
    assert len(metrics["data_warnings"]) == 2


def strict_json(path):
    """json.loads that refuses NaN and Infinity, as strict readers do."""
    import json

    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_json_text_writes_null_for_what_json_cannot_hold(tmp_path):
    from eas_vo.io.atomic import json_text

    path = tmp_path / "m.json"
    path.write_text(json_text({"a": float("nan"), "b": [1.5, float("inf"), {"c": -float("inf")}], "d": (2, "x")}))
    assert strict_json(path) == {"a": None, "b": [1.5, None, {"c": None}], "d": [2, "x"]}


def test_a_time_offset_that_misses_the_ground_truth_is_one_line_before_any_work(sequence_copy, tmp_path, capsys):
    out = tmp_path / "off"
    assert main(["run", "--dataset", str(sequence_copy), "--time-offset", "-9", "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "covers none of the" in err and "time offset -9 s" in err
    assert not out.exists()


def test_an_offset_that_cannot_be_estimated_is_said_and_not_claimed(sequence_copy, tmp_path, capsys):
    """Ground truth over the first 0.5 s of 2: --time-offset auto cannot estimate the offset,
    says so, measures the errors with 0 s and does not call that estimated."""
    gt = sequence_copy / "groundtruth.txt"
    rows = [line for line in gt.read_text().splitlines(keepends=True) if not line.startswith("#")]
    t0 = float(rows[0].split()[0])
    gt.write_text("".join(line for line in rows if float(line.split()[0]) < t0 + 0.5))
    out = tmp_path / "auto"
    assert main(["run", "--dataset", str(sequence_copy), "--time-offset", "auto", "--out", str(out), "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["time_offset_s"] == 0.0 and metrics["time_offset_estimated"] is False
    assert any("could not be estimated" in w for w in metrics["data_warnings"])
    said = capsys.readouterr()
    assert "could not be estimated" in said.err and "time offset" not in said.out


def test_results_are_strict_json_with_or_without_ground_truth(sequence_copy, tmp_path):
    assert main(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "gt"), "--quiet"]) == 0
    assert strict_json(tmp_path / "gt" / "metrics.json")["ape_mean_rad"] > 0
    (sequence_copy / "groundtruth.txt").unlink()
    assert main(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "nogt"), "--quiet"]) == 0
    metrics = strict_json(tmp_path / "nogt" / "metrics.json")
    assert "ape_mean_rad" not in metrics and metrics["frames_evaluated"] == 0


@pytest.mark.parametrize(
    "argv, says, usage",
    [
        (["run", "--set", "run.imu_time_offset_s=nan"], "imu_time_offset_s = nan is out of range", False),
        (["run", "--set", "run.imu_rotvec_cam=[0.0, nan, 0.0]"], "imu_rotvec_cam", False),
        (
            [
                "run",
                "--set",
                "backend.imu_rotvec_cam=[0.0, 0.1, 0.0]",
                "--set",
                "tracker.imu_rotvec_cam=[0, 0, 0]",
                "--backend",
                "gtsam",
            ],
            "tracker.imu_rotvec_cam = [0, 0, 0], backend.imu_rotvec_cam = [0.0, 0.1, 0.0]: the rig has one IMU; set run.imu_rotvec_cam only",
            False,
        ),
        (["simulate", "--seed", "-1", "--out", "{tmp}/sim"], "seed = -1 is out of range", False),
        (["compare", "--jobs", "0", "--out", "{tmp}/cmp"], "--jobs: must be at least 1", True),
        (
            ["run", "--duration", "0", "--out", "{tmp}/run"],
            "argument --duration: must be more than 0 seconds, got 0",
            True,
        ),
        (
            ["compare", "--start", "-1", "--out", "{tmp}/cmp"],
            "argument --start: must be at least 0 seconds, got -1",
            True,
        ),
        (
            ["run", "--start", "inf", "--out", "{tmp}/run"],
            "argument --start: must be at least 0 seconds, got inf",
            True,
        ),
        (
            ["reproduce", "table1", "--duration", "nan", "--out", "{tmp}/rep"],
            "argument --duration: must be more than 0 seconds",
            True,
        ),
        (
            ["evaluate", "--dataset", "{tmp}", "--estimate", "{tmp}/e.txt", "--max-diff", "-0.1"],
            "argument --max-diff: must be at least 0",
            True,
        ),
        (["run", "--frobnicate"], "unrecognized arguments: --frobnicate", True),
        (["rn"], "invalid choice: 'rn'", True),
    ],
)
def test_nonsense_values_and_usage_errors_are_one_line(argv, says, usage, tmp_path, capsys):
    """A configuration's value exits with 1, an option's (argparse's usage error) with 2."""
    err = one_line_failure([a.replace("{tmp}", str(tmp_path)) for a in argv], capsys, usage=usage)
    assert says in err
    assert not any(tmp_path.iterdir())


def test_evaluate_names_the_origin_alignment_for_a_rotation_only_trajectory(short_sequence, tmp_path, capsys):
    """eas-vo's own trajectory.tum: positions 0, which the default sim3 alignment cannot align."""
    from eas_vo.datasets.ecd import EcdFolderDataset
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum

    gt = EcdFolderDataset(short_sequence).ground_truth
    (tmp_path / "rotation_only.tum").write_text(
        format_tum(gt.t, np.zeros_like(gt.p_w_c), matrices_from_quats(gt.q_w_c))
    )
    argv = ["evaluate", "--dataset", str(short_sequence), "--estimate", str(tmp_path / "rotation_only.tum")]
    err = one_line_failure(argv, capsys)
    assert "sim3 alignment needs them to span a plane" in err and "--align origin" in err
    assert main([*argv, "--align", "origin"]) == 0 and "rotation APE mean 0.0000 rad" in capsys.readouterr().out


@pytest.mark.parametrize(
    "option", [["--backend", "gtsam", "--set", "backend.gyro=true"], ["--set", "tracker.predict='gyro'"]]
)
def test_an_option_that_needs_an_imu_refuses_a_dataset_without_one(sequence_copy, tmp_path, capsys, option):
    (sequence_copy / "imu.txt").unlink()
    err = one_line_failure(
        ["run", "--dataset", str(sequence_copy), *option, "--out", str(tmp_path / "out"), "--quiet"], capsys
    )
    assert "needs an IMU" in err and not (tmp_path / "out").exists()


#: calib.txt lines a careless user might write.
BAD_CALIBRATIONS = {
    "calib zeros": "0 0 0 0",
    "calib huge focal": "1e308 1e308 120 90",
    "calib nan": "200 nan 120 90",
    "calib tiny focal": "1e-6 1e-6 120 90",
    "calib principal point": "200 200 1e308 90",
    "calib negative principal point": "200 200 -5000 90 0 0 0 0 0",
    "calib distortion": "200 200 120 90 1e308 0 0 0 0",
}


def damage(seq, what):
    """Damage a private copy of the short sequence as a careless user might."""
    if what in BAD_CALIBRATIONS:
        (seq / "calib.txt").write_text(BAD_CALIBRATIONS[what] + "\n")
    elif what == "huge frames":  # every frame a 20000x20000 PNG (its header: nothing is decoded)
        header = b"\x89PNG\r\n\x1a\n" + b"\0\0\0\rIHDR" + (20000).to_bytes(4, "big") * 2 + bytes(20)
        for png in (seq / "images").iterdir():
            png.write_bytes(header)
    elif what == "empty groundtruth":
        (seq / "groundtruth.txt").write_text("")
    elif what == "huge quaternion":
        rows = (seq / "groundtruth.txt").read_text().splitlines()
        rows[3] = " ".join(rows[3].split()[:4] + ["1e300", "0", "0", "1"])
        (seq / "groundtruth.txt").write_text("\n".join(rows) + "\n")
    elif what == "one-line imu":
        (seq / "imu.txt").write_text((seq / "imu.txt").read_text().splitlines()[0] + "\n")


@pytest.mark.parametrize(
    "what, says",
    [
        ("calib zeros", "focal lengths fx = 0, fy = 0 px are not those of a 240x180 camera"),
        ("calib huge focal", "are not those of a 240x180 camera (24 to 24000 px)"),
        ("calib tiny focal", "focal lengths fx = 1e-06"),
        ("calib principal point", "principal point cx = 1e+308, cy = 90 px lies off the 240x180 sensor"),
        ("calib negative principal point", "principal point cx = -5000"),
        ("calib distortion", "out of range (|k| <= 10, |p| <= 1)"),
        ("huge frames", "frame 0 is 20000x20000, not an event camera's frame"),
        ("calib nan", "must be finite"),
        ("empty groundtruth", "groundtruth.txt: holds 0 row(s)"),
        ("huge quaternion", "groundtruth.txt:4: quaternion norm inf is not 1"),
        ("one-line imu", "imu.txt: holds 1 row(s)"),
    ],
)
def test_damaged_datasets_are_one_line_before_any_work(sequence_copy, tmp_path, capsys, what, says):
    """No warning either: a numpy RuntimeWarning would print its own lines."""
    damage(sequence_copy, what)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        err = one_line_failure(
            ["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "out"), "--quiet"], capsys
        )
    assert says in err and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "argv, says",
    [
        (["run", "--out", "{tmp}/a_file"], "is a file, not a folder"),
        (["run", "--config", "{tmp}"], "not a config file"),
        (["render", "--frames", "1", "--out", "{tmp}"], "is a folder; give the name of the file to write"),
        (["compare", "--frontends", ",", "--out", "{tmp}/cmp"], "names nothing"),
        (["simulate", "--out", "{tmp}", "--duration", "0.3"], "is not empty"),
    ],
)
def test_paths_in_the_way_are_one_line(tmp_path, capsys, argv, says):
    (tmp_path / "a_file").write_text("mine\n")
    usage = says == "names nothing"  # an option's value, not a path: a usage error
    err = one_line_failure([a.replace("{tmp}", str(tmp_path)) for a in argv], capsys, usage=usage)
    assert says in err and (tmp_path / "a_file").read_text() == "mine\n"


def test_simulate_overwrite_replaces_the_folder_whole(tmp_path):
    out = tmp_path / "sim"
    assert main(["simulate", "--out", str(out), "--duration", "0.6"]) == 0
    assert main(["simulate", "--out", str(out), "--duration", "0.3", "--overwrite"]) == 0
    listed = len((out / "images.txt").read_text().splitlines())
    assert len(list((out / "images").iterdir())) == listed  # no stale frames of the longer run
    assert not list(tmp_path.glob(".*.tmp"))


def test_an_absurd_window_is_one_line_without_numpy_warnings(short_sequence, tmp_path, capsys):
    err = one_line_failure(
        [
            "run",
            "--dataset",
            str(short_sequence),
            "--start",
            "1e308",
            "--duration",
            "1e308",
            "--out",
            str(tmp_path / "out"),
        ],
        capsys,
    )
    assert "holds 0 sample(s); at least 2 are needed" in err


def test_render_writes_over_a_file_only_with_overwrite_and_never_over_an_input(short_sequence, tmp_path, capsys):
    """An existing --out is kept without --overwrite; with it, a file of the dataset (a frame,
    also through a link to it) or the --config is still refused, so is a file that is no PNG
    (a trajectory); a PNG image is replaced."""
    dataset = tmp_path / "seq"  # the short sequence, its frames copied (its events linked: their cache is reused)
    shutil.copytree(short_sequence / "images", dataset / "images")
    for name in ("events.txt", "images.txt", "calib.txt"):
        (dataset / name).symlink_to(short_sequence / name)
    frame = dataset / "images" / "frame_00000005.png"
    kept = frame.read_bytes()
    estimate = tmp_path / "trajectory.tum"
    estimate.write_text("0 0 0 0 0 0 0 1\n")
    config = tmp_path / "render.toml"
    config.write_text(f'[run]\ndataset = "{dataset}"\n')
    (tmp_path / "frame.png").symlink_to(frame)
    render = ["render", "--frames", "1", "--frontends", "original", "--config", str(config)]
    for out, overwrite, says in (
        (estimate, [], "exists; choose another name or add --overwrite"),
        (frame, ["--overwrite"], "is the dataset"),
        (tmp_path / "frame.png", ["--overwrite"], "is the dataset"),
        (config, ["--overwrite"], "is the --config"),
        (estimate, ["--overwrite"], "is no PNG image, so not a file eas-vo wrote"),
    ):
        assert says in one_line_failure([*render, "--out", str(out), *overwrite], capsys)
    assert (
        frame.read_bytes() == kept
        and estimate.read_text() == "0 0 0 0 0 0 0 1\n"
        and config.read_text().startswith("[run]")
    )
    image = tmp_path / "gallery.png"
    image.write_bytes(frame.read_bytes())  # a PNG, as render's own
    assert main([*render, "--out", str(image), "--overwrite"]) == 0
    assert (
        image.read_bytes() != kept
        and image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        and not list(tmp_path.glob(".*.tmp"))
    )


@pytest.mark.parametrize(
    "command", [["run", "--overwrite"], ["export", "--overwrite"], ["compare", "--frontends", "original"]]
)
def test_an_output_folder_holding_the_config_file_is_refused_even_with_overwrite(
    short_sequence, tmp_path, capsys, command
):
    from helpers import mark_as_eas_vo_output

    out = tmp_path / "earlier"
    out.mkdir()
    config = out / "config.toml"  # an earlier run's resolved config, read again
    config.write_text(f'[run]\ndataset = "{short_sequence}"\nfrontend = "original"\nduration_s = 0.2\n')
    mark_as_eas_vo_output(out)
    err = one_line_failure([*command, "--config", str(config), "--out", str(out), "--quiet"], capsys)
    assert "holds the --config" in err and config.read_text().startswith("[run]\ndataset")
    assert sorted(p.name for p in out.iterdir()) == [".eas-vo-output", "config.toml"]


@pytest.mark.parametrize(
    "command", [["run", "--overwrite"], ["export", "--overwrite"], ["compare", "--frontends", "original"]]
)
@pytest.mark.parametrize("inside", [False, True])
def test_an_output_folder_that_is_or_holds_the_dataset_is_refused(short_sequence, tmp_path, capsys, command, inside):
    """--out the dataset's folder, or the folder holding it (marked as an eas-vo output, as
    `eas-vo simulate` leaves it): refused, nothing written there."""
    from helpers import mark_as_eas_vo_output

    dataset = tmp_path / "data" / "seq"
    shutil.copytree(short_sequence, dataset, ignore=shutil.ignore_patterns(".*"))
    out = dataset if inside else dataset.parent
    mark_as_eas_vo_output(out)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    err = one_line_failure(
        [*command, "--dataset", str(dataset), "--duration", "0.2", "--out", str(out), "--quiet"], capsys
    )
    assert f"holds the dataset {dataset}" in err
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_version_is_the_installed_distributions(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out == f"eas-vo {version('eas-vo')}\n"
