"""`eas-vo reproduce rotation` end to end without the internet: two short simulated sequences
serve as STAND-INS for the four ECD rotation sequences (a loopback server under their names);
the published rows are quoted in the table, never computed."""

import json

import numpy as np
import pytest

from eas_vo.cli.main import main
from eas_vo.evaluation.rotation_protocol import DURATION_S, score
from eas_vo.experiments.rotation import METHODS, PUBLISHED, SEQUENCES
from eas_vo.geometry.rotations import matrices_from_quats
from eas_vo.io.tum import read_tum
from eas_vo.registry import open_dataset
from eas_vo.types import PoseSeries
from helpers import publish_sequences


@pytest.fixture(scope="module")
def other_sequence(tmp_path_factory):
    from eas_vo.datasets.simulator import SimConfig, simulate

    folder = tmp_path_factory.mktemp("sim") / "other"
    simulate(SimConfig(duration_s=2.0, seed=7), folder)
    return folder


@pytest.fixture
def stand_ins(data_server, short_sequence, other_sequence, tmp_path, monkeypatch):
    folder, url, _, hits = data_server
    registry = tmp_path / "registry.txt"
    served = dict(zip(SEQUENCES, (short_sequence, other_sequence, other_sequence, short_sequence)))
    publish_sequences(folder, served, registry)
    monkeypatch.setenv("EAS_VO_DATA_URL", url)
    monkeypatch.setenv("EAS_VO_DATA_REGISTRY", str(registry))
    monkeypatch.setenv("EAS_VO_DATA_DIR", str(tmp_path / "data"))
    return hits


def test_the_rotation_benchmark_in_one_command_beside_the_published_rows(stand_ins, tmp_path, capsys):
    out = tmp_path / "rot"
    argv = ["reproduce", "rotation", "--out", str(out), "--jobs", "2", "--quiet"]  # the protocol's 30 s: all 2 s
    assert main(argv) == 0
    assert all(stand_ins[f"{s}.zip"] == 1 for s in SEQUENCES)
    data = json.loads((out / "rotation.json").read_text())
    rows = data["ours"]
    assert len(rows) == len(SEQUENCES) * len(METHODS) and {r["status"] for r in rows} == {"ok"}
    table = (out / "rotation.md").read_text()
    assert "aligned to it by the one pose at t0 = 1.0 s" in table and "Table III" in table
    assert "Protocol: the first 30 s of each sequence;" in table
    absolute = table.split("## Absolute error")[1].split("## ")[0]
    relative = table.split("## Relative error")[1].split("## ")[0]
    for method, per_seq in PUBLISHED.items():  # quoted as published, in the sequences' order
        line = next(x for x in absolute.splitlines() if x.startswith(f"| published: {method} |"))
        quoted = [c.strip() for c in line.strip("|").split("|")[1:]]
        assert quoted == [f"{v[0]:.3f}" if v else "fails" for v in (per_seq[s] for s in SEQUENCES)]
    assert "| published: CMax-SLAM (linear spline) | 4.953 | 5.653 | 5.418 | 3.380 |" in absolute
    assert "| published: RTPT | 3.167 | 9.423 | 2.375 | 1.991 |" in relative
    # each of our cells: its figures are the protocol's on its own trajectory, recomputed here
    for r in rows:
        line = next(x for x in absolute.splitlines() if x.startswith(f"| ours: {r['label']} |"))
        cells = [c.strip() for c in line.strip("|").split("|")[1:]]
        assert cells[SEQUENCES.index(r["dataset_name"])] == f"{r['absolute_rms_deg']:.3f}"
        tum = read_tum(out / r["folder"] / "trajectory.tum")
        dataset = open_dataset(f"ecd:{r['dataset_name']}")
        start = dataset.frame_times()[0]  # the run's start: its first frame
        again = score(PoseSeries(tum.t, tum.p_w_c, tum.q_w_c), dataset.ground_truth, start, DURATION_S).summary()
        assert again["absolute_rms_deg"] == pytest.approx(r["absolute_rms_deg"], rel=1e-9)
        assert again["relative_rms_deg_s"] == pytest.approx(r["relative_rms_deg_s"], rel=1e-9)
        assert 8 <= r["spans_scored"] <= 11 and r["realtime_factor"] > 0  # spans the last pose covers
    by = {(r["label"], r["dataset_name"]): r for r in rows}
    gyro = "gyro alone (gtsam, dead reckoning)"
    for s in SEQUENCES:  # the simulated gyro integrates to within a degree over 2 s; frames and events measure
        assert by[(gyro, s)]["absolute_rms_deg"] < 2.0
        assert by[("best.toml with gyro", s)]["absolute_rms_deg"] < 3.0
    folder = out / by[("cmax + chain (events only)", SEQUENCES[0])]["folder"]
    assert json.loads((folder / "metrics.json").read_text())["tracker"] == "cmax"
    for s in SEQUENCES:
        assert (out / f"rotation_{s}.png").stat().st_size > 20_000
    capsys.readouterr()
    cell = by[("cmax + chain (events only)", SEQUENCES[1])]  # an external tool's TUM file, scored the same way
    estimate = out / cell["folder"] / "trajectory.tum"
    evaluated = tmp_path / "evaluated"
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                f"ecd:{SEQUENCES[1]}",
                "--estimate",
                str(estimate),
                "--protocol",
                "cmax-slam",
                "--out",
                str(evaluated),
            ]
        )
        == 0
    )
    said = capsys.readouterr().out
    assert (
        f"absolute RMS {cell['absolute_rms_deg']:.4f} deg, relative over 1 s RMS {cell['relative_rms_deg_s']:.4f} deg/s"
        in said
    )
    assert json.loads((evaluated / "metrics.json").read_text())["absolute_rms_deg"] == pytest.approx(
        cell["absolute_rms_deg"], rel=1e-12
    )
    assert (evaluated / "rotation_errors.png").stat().st_size > 20_000
    assert main(argv) == 0  # resumable: nothing runs again, nothing is fetched again
    assert f"{len(rows)} cells (0 run, {len(rows)} already complete, 0 failed)" in capsys.readouterr().out
    assert stand_ins[f"{SEQUENCES[0]}.zip"] == 1


def test_rotation_takes_no_configuration_of_its_own(stand_ins, tmp_path, capsys):
    assert main(["reproduce", "rotation", "--config", "best", "--out", str(tmp_path / "r")]) != 0
    assert "rotation's methods carry their own" in capsys.readouterr().err
    assert not any(stand_ins.values())  # refused before any download


def test_the_gyro_alone_is_its_integration(short_sequence):
    """The `blind` tracker's graph holds the gyro alone: its trajectory is the gyro integrated."""
    from eas_vo import config, pipeline
    from eas_vo.geometry.rotations import gyro_rotation

    cfg = config.resolve(
        None,
        {"dataset": str(short_sequence), "tracker": "blind", "backend": "gtsam", "duration_s": 1.5},
        ["backend.gtsam.gyro=true"],
    )
    result = pipeline.run(cfg, None)
    imu = open_dataset(str(short_sequence)).imu
    t = result.t
    for k in (5, len(t) - 1):
        R = result.R_w_c[0].T @ result.R_w_c[k]
        by_gyro = gyro_rotation(imu, t[0], t[k])
        assert np.degrees(np.arccos(np.clip((np.trace(R.T @ by_gyro) - 1) / 2, -1, 1))) < 0.05
    assert matrices_from_quats(np.array([[0, 0, 0, 1.0]])).shape == (1, 3, 3)


def drifting_estimate(sequence, path, shift_s: int = 0, step: int = 4, span_s=(-np.inf, np.inf)) -> None:
    """A TUM file of `sequence`'s ground truth every `step`-th pose within `span_s`, drifting at
    3 deg/s about the world's z axis, on the clock shifted by `shift_s`; one pose repeated and
    two swapped, as files other tools write."""
    from eas_vo.geometry.rotations import rotvec_to_matrix
    from eas_vo.io.tum import format_tum

    gt = open_dataset(str(sequence)).ground_truth
    keep = np.flatnonzero((gt.t >= span_s[0]) & (gt.t <= span_s[1]))[::step]
    t = gt.t[keep]
    R = rotvec_to_matrix(np.outer(np.radians(3.0) * t, [0, 0, 1.0])) @ matrices_from_quats(gt.q_w_c[keep])
    lines = format_tum(t + shift_s, gt.p_w_c[keep], R).splitlines(keepends=True)
    lines.insert(5, lines[5])  # a repeated time
    lines[10], lines[11] = lines[11], lines[10]  # out of order
    path.write_text("".join(lines))


def test_evaluate_scores_a_file_as_other_tools_write_it_on_any_clock(short_sequence, tmp_path, capsys):
    from helpers import retimed

    estimate = tmp_path / "est.tum"
    drifting_estimate(short_sequence, estimate)
    assert (
        main(["evaluate", "--dataset", str(short_sequence), "--estimate", str(estimate), "--protocol", "cmax-slam"])
        == 0
    )
    said = capsys.readouterr().out
    # over any 1 s the drift adds 3 degrees (against the ground truth smoothed over 50 ms: to 0.01)
    assert relative_deg_s(said) == pytest.approx(3.0, abs=0.01)
    unix = tmp_path / "unix"
    import shutil

    shutil.copytree(short_sequence, unix)
    for name in ("events.txt", "images.txt", "groundtruth.txt", "imu.txt"):
        retimed(unix / name, shift_s=1_700_000_000)
    moved = tmp_path / "unix.tum"
    drifting_estimate(short_sequence, moved, shift_s=1_700_000_000)
    assert main(["evaluate", "--dataset", str(unix), "--estimate", str(moved), "--protocol", "cmax-slam"]) == 0
    again = capsys.readouterr().out
    absolute = [x.split("absolute RMS ")[1].split(" deg")[0] for x in (said, again)]
    assert absolute[0] == absolute[1] and relative_deg_s(again) == relative_deg_s(said)


def relative_deg_s(said: str) -> float:
    return float(said.split("relative over 1 s RMS ")[1].split(" deg/s")[0])


def test_evaluate_says_in_one_line_what_the_protocol_cannot_score(short_sequence, tmp_path, capsys):
    short = tmp_path / "short.tum"
    drifting_estimate(short_sequence, short, span_s=(0.5, 1.4))  # covers t0 = 1 s, no whole 1 s span of the grid
    assert (
        main(["evaluate", "--dataset", str(short_sequence), "--estimate", str(short), "--protocol", "cmax-slam"]) == 0
    )
    assert "relative over 1 s RMS none (the estimate covers no whole 1 s span)" in capsys.readouterr().out
    early = tmp_path / "early.tum"
    drifting_estimate(short_sequence, early, span_s=(-1.0, 0.6))
    import shutil

    no_truth = tmp_path / "no_truth"
    shutil.copytree(short_sequence, no_truth)
    (no_truth / "groundtruth.txt").unlink()
    cases = [
        (short_sequence, ["--estimate", str(early)], "does not cover the alignment time, 1 s after the start"),
        (short_sequence, ["--estimate", str(short), "--align", "se3"], "--align: evo's options"),
        (no_truth, ["--estimate", str(short)], "has no ground truth to evaluate against"),
    ]
    for dataset, extra, says in cases:
        argv = ["evaluate", "--dataset", str(dataset), "--protocol", "cmax-slam", *extra]
        assert main(argv) != 0
        err = capsys.readouterr().err.strip()
        assert says in err and len(err.splitlines()) == 1, err


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--duration", "0.5"], "--duration 0.5: the protocol aligns at 1 s"),
        (["--backends", "chain"], "--backends belongs to table1"),
        (["--runs", "3"], "--runs belongs to table2"),
    ],
)
def test_rotation_refuses_what_it_cannot_use_before_any_download(stand_ins, tmp_path, capsys, argv, says):
    assert main(["reproduce", "rotation", "--out", str(tmp_path / "r"), *argv]) != 0
    assert says in capsys.readouterr().err
    assert not any(stand_ins.values())
