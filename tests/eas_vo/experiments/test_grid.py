"""`eas-vo compare`: the grid, its Table 1, resuming, failing cells, sweeps, parallel runs."""

import contextlib
import csv
import io
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.cli.main import main
from eas_vo.experiments.cells import Cell, plan
from eas_vo.experiments.results import table_markdown
from helpers import hostile_settings


@pytest.fixture(scope="module")
def grid(short_sequence, tmp_path_factory):
    out = tmp_path_factory.mktemp("cmp") / "grid"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original,eas",
        "--backends",
        "chain,gtsam",
        "--out",
        str(out),
        "--jobs",
        "2",
        "--quiet",
    ]
    assert main(argv) == 0
    return out, argv


def test_table_equals_each_cells_metrics(grid):
    out, _ = grid
    rows = json.loads((out / "table.json").read_text())
    assert len(rows) == 4 and {r["status"] for r in rows} == {"ok"}
    for r in rows:
        metrics = json.loads((out / r["folder"] / "metrics.json").read_text())
        assert r["nc_mean"] == metrics["nc_mean"] and r["ape_mean_rad"] == metrics["ape_mean_rad"]
        assert (out / r["folder"] / "rotation.png").exists()
    md = (out / "table.md").read_text()
    name = rows[0]["dataset_name"]
    assert md.splitlines()[0] == (
        f"| Source type | {name} klt+chain = klt+gtsam: average NC | {name} klt+chain = klt+gtsam: average APE [rad] |"
    )
    assert md.count("**") >= 4
    assert b"\r" not in (out / "table.csv").read_bytes()
    csv_lines = (out / "table.csv").read_text().splitlines()
    assert len(csv_lines) == 5 and csv_lines[0].startswith("dataset,frontend,tracker,backend,method")
    assert (out / "ape_bars.png").exists() and (out / "ape_time.png").exists()


def test_a_pose_graph_on_consecutive_edges_alone_is_found_to_be_the_chain(grid):
    """klt gives only consecutive edges without keyframes: gtsam then returns the chain's
    trajectory, which compare finds and says (one column, one panel) instead of repeating it."""
    out, _ = grid
    rows = json.loads((out / "table.json").read_text())
    assert {(r["backend"], r["same_as"]) for r in rows} == {("chain", ""), ("gtsam", "klt+chain")}


def test_a_second_invocation_runs_nothing(grid, capsys):
    out, argv = grid
    before = {p: p.stat().st_mtime_ns for p in out.rglob("metrics.json")}
    assert main(argv) == 0
    assert "4 cells (0 run, 4 already complete, 0 failed)" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in out.rglob("metrics.json")} == before


def test_a_failing_cell_is_reported_the_rest_complete_and_the_exit_says_so(short_sequence, tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "slice",
        "--backends",
        "chain",
        "--sweep",
        "run.start_s=0,100",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(argv) == 1
    captured = capsys.readouterr()
    assert "2 cells (2 run, 0 already complete, 1 failed)" in captured.out
    assert "holds 0 sample(s)" in captured.err
    rows = {r["sweep"]: r for r in json.loads((out / "table.json").read_text())}
    assert rows["run.start_s=100"]["status"] == "failed" and rows["run.start_s=0"]["status"] == "ok"
    assert rows["run.start_s=100"]["ape_mean_rad"] is None  # strict JSON: null, never NaN
    assert "slice (run.start_s=0)" in (out / "table.md").read_text()
    assert (out / "ape_sweep.png").exists()  # a numeric sweep: APE and NC against it
    failed = out / rows["run.start_s=100"]["folder"]
    assert (failed / "error.txt").read_text().strip() == rows["run.start_s=100"]["error"]
    assert main(argv) == 1  # the failed cell runs again into its own folder (no "did not write" refusal)
    assert "2 cells (1 run, 1 already complete, 1 failed)" in capsys.readouterr().out


def test_a_data_warning_is_said_once_with_the_cells_it_came_from(short_sequence, tmp_path, capsys):
    """The IMU configured a quarter turn off: both backends' cells see the same gyro against the
    same tracks, and stderr says it once naming both, on the run and on the resume."""
    out = tmp_path / "imu"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "eas",
        "--backends",
        "chain,gtsam",
        "--config",
        "best",
        "--set",
        "run.imu_rotvec_cam=[0.0, 0.0, 1.5708]",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    for _ in range(2):
        assert main(argv) == 0
        lines = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
        assert len(lines) == 1 and "the IMU looks mounted as run.imu_rotvec_cam = [0, 0, 0] (the identity, " in lines[0]
        rows = json.loads((out / "table.json").read_text())
        assert lines[0].endswith(f"(cells {rows[0]['folder']}, {rows[1]['folder']})")
        assert rows[0]["data_warnings"] == rows[1]["data_warnings"] and len(rows[0]["data_warnings"]) == 1


def test_a_configuration_error_stops_compare_before_any_work(short_sequence, tmp_path, capsys):
    out = tmp_path / "bad"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "slice",
        "--backends",
        "chain",
        "--sweep",
        "frontend.n=2000,0",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "n = 0 is out of range" in err
    assert not out.exists()


def test_sweep_curves_follow_one_numeric_key():
    from eas_vo.experiments.results import sweep_curves, table_rows

    cells = [
        Cell("d", f, "klt", "chain", (("dataset.illumination", v),))
        for f in ("eas", "slice")
        for v in ("1", "0.1", "0.5")
    ]
    results = {
        c: {"status": "ok", "nc_mean": 10.0 * float(c.sweep[0][1]), "ape_mean_rad": 1.0 / float(c.sweep[0][1])}
        for c in cells
    }
    results[cells[0]] = {"status": "failed", "error": "boom"}
    key, curves = sweep_curves(cells, table_rows(cells, results))
    assert key == "dataset.illumination" and set(curves) == {("d", "klt+chain", "eas"), ("d", "klt+chain", "slice")}
    assert curves[("d", "klt+chain", "slice")].tolist() == [[0.1, 1.0, 10.0], [0.5, 5.0, 2.0], [1.0, 10.0, 1.0]]
    assert len(curves[("d", "klt+chain", "eas")]) == 2  # the failed cell is left out
    words = [Cell("d", "eas", "klt", "chain", (("tracker.geometry", g),)) for g in ("rotation", "essential")]
    assert sweep_curves(words, table_rows(words, {})) is None


def test_one_and_two_jobs_give_the_same_table(grid, short_sequence, tmp_path):
    out, argv = grid
    serial = tmp_path / "serial"
    argv = [a if a != str(out) else str(serial) for a in argv]
    argv[argv.index("--jobs") + 1] = "1"
    assert main(argv) == 0
    strip = lambda rows: [{k: v for k, v in r.items() if k != "folder"} for r in rows]  # noqa: E731
    assert strip(json.loads((serial / "table.json").read_text())) == strip(json.loads((out / "table.json").read_text()))


def test_plan_is_the_cartesian_product():
    from eas_vo.experiments.cells import Method, grid_methods

    cells = plan(
        ["a", "b"], ["x"], grid_methods(["klt", "other"], ["chain", "gtsam"]), ["frontend.n=1,2", "frontend.beta=3,4,5"]
    )
    assert len(cells) == 2 * 2 * 2 * 2 * 3
    assert Cell("a", "x", "other", "chain", (("frontend.n", "1"), ("frontend.beta", "3")), "a") in cells
    (smoothed,) = plan(["a"], ["x"], [Method("klt", "gtsam", (("tracker.klt.keyframe_interval", "3"),))], [])
    assert (
        smoothed.folder == "a/x_klt_gtsam_keyframe_interval-3"
        and smoothed.method.label == "klt+gtsam (keyframe_interval=3)"
    )


def test_a_tracker_of_events_alone_is_one_cell_per_dataset_with_the_none_frontend():
    from eas_vo.experiments.cells import grid_methods

    cells = plan(["a", "b"], ["original", "eas", "ts"], grid_methods(["klt", "cmax"], ["chain"]), [])
    assert len(cells) == 2 * 3 + 2
    assert [c.frontend for c in cells if c.tracker == "cmax"] == ["no_image", "no_image"]
    assert {c.frontend for c in cells if c.tracker == "klt"} == {"original", "eas", "ts"}


def test_compares_default_grid_runs_the_smoothed_method_beside_the_chain(short_sequence, tmp_path):
    """No --backends: klt+chain as the paper and klt+gtsam on klt's keyframe edges (interval 3,
    the cell's resolved config says so), which is not the chain's trajectory."""
    import tomllib

    out = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                "--dataset",
                str(short_sequence),
                "--frontends",
                "eas",
                "--duration",
                "1",
                "--out",
                str(out),
                "--jobs",
                "2",
                "--quiet",
            ]
        )
        == 0
    )
    rows = {r["method"]: r for r in json.loads((out / "table.json").read_text())}
    assert list(rows) == ["klt+chain", "klt+gtsam (keyframe_interval=3)"]
    intervals = {
        m: tomllib.loads((out / r["folder"] / "config.toml").read_text())["tracker"]["keyframe_interval"]
        for m, r in rows.items()
    }
    assert intervals == {"klt+chain": 0, "klt+gtsam (keyframe_interval=3)": 3}
    assert [r["same_as"] for r in rows.values()] == ["", ""]
    assert "klt+gtsam (keyframe_interval=3): average APE [rad]" in (out / "table.md").read_text().splitlines()[0]


def test_datasets_sharing_a_folder_name_never_share_cells(short_sequence, tmp_path, capsys):
    """Two recordings both called `seq`: their cells, columns and reruns stay apart."""
    import shutil

    a, b = tmp_path / "a" / "seq", tmp_path / "b" / "seq"
    shutil.copytree(short_sequence, a)
    shutil.copytree(short_sequence, b)
    lines = (b / "images.txt").read_text().splitlines()
    (b / "images.txt").write_text("\n".join(lines[:20]) + "\n")  # b: a different (shorter) sequence
    out = tmp_path / "cmp"
    argv = [
        "compare",
        "--dataset",
        str(a),
        "--dataset",
        str(b),
        "--frontends",
        "original",
        "--backends",
        "chain",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(argv) == 0
    first = capsys.readouterr().out
    rows = {r["dataset"]: r for r in json.loads((out / "table.json").read_text())}
    assert rows[str(a)]["folder"] != rows[str(b)]["folder"]
    assert "a-seq klt+chain: average NC" in first and "b-seq klt+chain: average NC" in first
    frames = {d: json.loads((out / r["folder"] / "metrics.json").read_text())["frames"] for d, r in rows.items()}
    assert frames[str(b)] == 20 and frames[str(a)] > 20
    assert main(argv) == 0  # the rerun reads each its own
    assert {r["dataset"]: r["nc_mean"] for r in json.loads((out / "table.json").read_text())} == {
        d: r["nc_mean"] for d, r in rows.items()
    }


def test_a_cell_is_reused_only_if_made_with_the_same_inputs(short_sequence, tmp_path, capsys):
    out = tmp_path / "cmp"
    base = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original",
        "--backends",
        "chain",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(base + ["--duration", "1"]) == 0
    assert "1 cells (1 run, 0 already complete" in capsys.readouterr().out
    assert main(base + ["--duration", "1"]) == 0
    assert "1 cells (0 run, 1 already complete" in capsys.readouterr().out
    assert main(base) == 0  # no --duration: other inputs, so it runs again
    assert "1 cells (1 run, 0 already complete" in capsys.readouterr().out
    (row,) = json.loads((out / "table.json").read_text())
    assert json.loads((out / row["folder"] / "metrics.json").read_text())["frames"] > 25


def test_markdown_marks_the_best_of_each_column():
    rows = [
        {
            "dataset": "d",
            "method": "klt+chain",
            "frontend": f,
            "sweep": "",
            "status": "ok",
            "nc_mean": nc,
            "ape_mean_rad": ape,
            "same_as": "",
        }
        for f, nc, ape in (("original", 20.0, 0.6), ("eas", 60.0, 0.2))
    ]
    md = table_markdown(rows)
    assert "| original | 20 | 0.600 |" in md and "| eas | **60** | **0.200** |" in md


@pytest.mark.parametrize("ncs", [(0.0, 0.0), (0.0, None), (0.0, float("nan"))])
def test_an_nc_of_zero_is_never_the_best(ncs):
    """NC 0 counts no correspondence (nothing tracked, or an event tracker's): nothing to bold,
    in table.md or table.csv; the best of the real values still is."""
    from eas_vo.experiments.results import table_csv

    rows = [
        {
            "dataset": "d",
            "method": "cmax+chain",
            "frontend": f,
            "sweep": "",
            "status": "ok",
            "nc_mean": nc,
            "ape_mean_rad": ape,
            "same_as": "",
        }
        for f, nc, ape in (("no_image", ncs[0], 0.05), ("other", ncs[1], 0.08))
    ]
    rows += [
        {**rows[0], "method": "klt+chain", "frontend": f, "nc_mean": nc} for f, nc in (("eas", 60.0), ("histeq", 0.0))
    ]
    lines = table_markdown(rows).splitlines()
    assert lines[2].startswith("| no_image | 0 | **0.050** |") and "**0**" not in "".join(lines)
    assert lines[4] == "| eas |  |  | **60** | **0.050** |" and lines[5].startswith("| histeq |  |  | 0 |")
    assert [r["best_nc"] for r in csv.DictReader(io.StringIO(table_csv(rows)))] == ["0", "0", "1", "0"]


def test_the_motion_table_gives_angular_velocity_and_rpe_with_the_best_in_bold():
    from eas_vo.experiments.results import MOTION_FIGURES

    rows = [
        {
            "dataset": "d",
            "method": m,
            "frontend": f,
            "sweep": "",
            "status": "ok",
            "nc_mean": 0.0,
            "ape_mean_rad": 0.1,
            "omega_rms_deg_s": w,
            "rpe_1s_mean_deg": r,
            "same_as": "",
        }
        for m, f, w, r in (("klt+chain", "eas", 30.2, 6.5), ("cmax+chain", "no_image", 7.0, 2.68))
    ]
    rows.append({**rows[0], "frontend": "original", "status": "failed", "error": "boom"})
    lines = table_markdown(rows, MOTION_FIGURES).splitlines()
    assert lines[0] == (
        "| Source type | d klt+chain: omega RMS [deg/s] | d klt+chain: RPE 1 s [deg] "
        "| d cmax+chain: omega RMS [deg/s] | d cmax+chain: RPE 1 s [deg] |"
    )
    assert lines[2:] == [
        "| eas | **30.2** | **6.50** |  |  |",
        "| no_image |  |  | **7.0** | **2.68** |",
        "| original | failed | boom |  |  |",
    ]


def test_markdown_has_one_header_row_and_a_column_pair_per_distinct_method():
    """Two sequences x three methods, the second of which repeats the first on sequence a only:
    one header row naming sequence, method and figure; the repeated method's column dropped
    where it repeats and named in the header of the one it repeats."""
    rows = [
        {
            "dataset": d,
            "dataset_name": d,
            "method": m,
            "frontend": f,
            "sweep": "",
            "status": "ok",
            "nc_mean": nc + k,
            "ape_mean_rad": 0.1 * (k + 1),
            "same_as": "klt+chain" if (d, m) == ("a", "klt+gtsam") else "",
        }
        for d in ("a", "b")
        for k, m in enumerate(("klt+chain", "klt+gtsam", "other+chain"))
        for f, nc in (("original", 20), ("eas", 60))
    ]
    lines = table_markdown(rows).splitlines()
    assert lines[0] == (
        "| Source type | a klt+chain = klt+gtsam: average NC | a klt+chain = klt+gtsam: average APE [rad] "
        "| a other+chain: average NC | a other+chain: average APE [rad] "
        "| b klt+chain: average NC | b klt+chain: average APE [rad] | b klt+gtsam: average NC "
        "| b klt+gtsam: average APE [rad] | b other+chain: average NC | b other+chain: average APE [rad] |"
    )
    assert lines[1] == "|" + "---|" * 11
    assert lines[2:] == [
        "| original | 20 | **0.100** | 22 | **0.300** | 20 | **0.100** | 21 | **0.200** | 22 | **0.300** |",
        "| eas | **60** | **0.100** | **62** | **0.300** | **60** | **0.100** | **61** | **0.200** | **62** | **0.300** |",
    ]


def _write_tum(path: Path, t, R) -> None:
    from eas_vo.io.tum import format_tum

    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(format_tum(np.asarray(t, float), np.zeros((len(t), 3)), R))


def test_identical_methods_are_found_exactly(tmp_path):
    """Known answers on written trajectories: a copy (one with every quaternion negated, the same
    rotations) is identical; a rotation moved by 1e-7 rad, a shifted timestamp, another NC or a
    failed cell is not; a third copy names the first method, never the second."""
    from scipy.spatial.transform import Rotation

    from eas_vo.experiments.results import mark_identical, table_rows

    R = Rotation.from_rotvec(np.random.default_rng(0).normal(0, 0.5, (30, 3))).as_matrix()
    t = 0.05 * np.arange(30)
    tilted = R.copy()
    tilted[17] = Rotation.from_rotvec([1e-7, 0, 0]).as_matrix() @ R[17]
    methods = {
        "a+x": (t, R),
        "b+x": (t, R),
        "c+x": (t, R),
        "tilt+x": (t, tilted),
        "late+x": (t + np.r_[np.zeros(29), 1e-3], R),
        "nc+x": (t, R),
        "failed+x": (t, R),
    }
    cells = [Cell("d", f, m.split("+")[0], "x", ()) for m in methods for f in ("eas", "slice")]
    for cell in cells:
        _write_tum(tmp_path / cell.folder / "trajectory.tum", *methods[cell.method.label])
    text = (tmp_path / cells[2].folder / "trajectory.tum").read_text().splitlines()  # b+x eas: every quaternion negated
    (tmp_path / cells[2].folder / "trajectory.tum").write_text(
        "".join(" ".join(v[:4] + [f"{-float(q):.12f}" for q in v[4:]]) + "\n" for v in (line.split() for line in text))
    )
    results = {c: {"status": "ok", "nc_mean": 50.0 + (c.tracker == "nc"), "ape_mean_rad": 0.1} for c in cells}
    results[cells[-1]] = {"status": "failed", "error": "boom"}
    same_as = {r["method"]: r["same_as"] for r in mark_identical(tmp_path, cells, table_rows(cells, results))}
    assert same_as == {"a+x": "", "b+x": "a+x", "c+x": "a+x", "tilt+x": "", "late+x": "", "nc+x": "", "failed+x": ""}


def test_dask_executor_gives_the_same_table(grid, tmp_path):
    distributed = pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
    out, argv = grid
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        target = tmp_path / "dask"
        argv = [a if a != str(out) else str(target) for a in argv] + [
            "--executor",
            "dask",
            "--scheduler",
            cluster.scheduler_address,
        ]
        assert main(argv) == 0
    strip = lambda rows: [{k: v for k, v in r.items() if k != "folder"} for r in rows]  # noqa: E731
    assert strip(json.loads((target / "table.json").read_text())) == strip(json.loads((out / "table.json").read_text()))


@pytest.fixture(scope="module")
def one_cell(short_sequence, tmp_path_factory):
    """A finished one-cell compare folder (1 s of the short sequence), its argv and its table row."""
    out = tmp_path_factory.mktemp("cmp") / "one"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "eas",
        "--backends",
        "chain",
        "--duration",
        "1",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(argv) == 0
    (row,) = json.loads((out / "table.json").read_text())
    return out, argv, row


def _damage(folder, data) -> bool:
    """Damage one cell folder as a crash, a careless user or an old version would; True if the
    damage leaves its run whole (so it may be reused)."""
    from eas_vo.pipeline import RUN_FILES

    name = data.draw(st.sampled_from(RUN_FILES))
    kind = data.draw(st.sampled_from(["delete", "garbage", "cut", "identity", "partial", "stray", "touch"]))
    path = folder / name
    if kind == "delete":
        path.unlink()
    elif kind == "garbage":
        path.write_bytes(data.draw(st.binary(max_size=64)))
    elif kind == "cut":
        path.write_bytes(path.read_bytes()[: data.draw(st.integers(0, 20))])
    elif kind == "identity":
        identity = json.loads((folder / "identity.json").read_text())
        identity[data.draw(st.sampled_from(sorted(identity)))] = data.draw(st.sampled_from(["0.0.1", "/elsewhere", ""]))
        (folder / "identity.json").write_text(json.dumps(identity))
    elif kind == "partial":
        metrics = json.loads((folder / "metrics.json").read_text())
        (folder / "metrics.json").write_text(json.dumps({**metrics, "partial": True}))
    elif kind == "stray":
        (folder / "notes.txt").write_text("mine")
    else:
        os.utime(path, ns=(1, 1))
    return kind in ("stray", "touch") or (kind in ("garbage", "cut") and name not in ("metrics.json", "identity.json"))


@given(st.data())
@hostile_settings(max_examples=15)
def test_a_damaged_cell_folder_is_run_again_never_trusted(one_cell, data):
    """Random damage to a finished cell: the resumed compare either reuses it (the damage left
    the run whole and its inputs unchanged) or runs it again; the table is always the clean one
    and the folder ends whole."""
    from eas_vo.pipeline import RUN_FILES

    out, argv, row = one_cell
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "one"
        shutil.copytree(out, copy)
        may_reuse = _damage(copy / row["folder"], data)
        with contextlib.redirect_stdout(io.StringIO()) as said:
            assert main(argv[:-4] + [str(copy), "--jobs", "1", "--quiet"]) == 0
        reused = "0 run, 1 already complete" in said.getvalue()
        assert reused <= may_reuse, said.getvalue()
        (again,) = json.loads((copy / "table.json").read_text())
        assert {k: again[k] for k in ("status", "nc_mean", "ape_mean_rad")} == {
            k: row[k] for k in ("status", "nc_mean", "ape_mean_rad")
        }
        folder = copy / row["folder"]
        assert all((folder / f).is_file() for f in RUN_FILES)
        assert json.loads((folder / "identity.json").read_text()) == json.loads(
            (out / row["folder"] / "identity.json").read_text()
        )


def test_a_pool_never_has_more_workers_than_cells(short_sequence, tmp_path, monkeypatch):
    """`--jobs 100000` on two cells starts two workers, not a hundred thousand processes."""
    from concurrent.futures import ProcessPoolExecutor

    from eas_vo.experiments import grid

    sizes = []

    class Recording(ProcessPoolExecutor):
        def __init__(self, max_workers=None, *args, **kwargs):
            sizes.append(max_workers)
            super().__init__(max_workers, *args, **kwargs)

    monkeypatch.setattr(grid, "ProcessPoolExecutor", Recording)
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original,histeq",
        "--backends",
        "chain",
        "--duration",
        "0.5",
        "--out",
        str(tmp_path / "cmp"),
        "--jobs",
        "100000",
        "--quiet",
    ]
    assert main(argv) == 0
    assert sizes == [2]
    assert main(argv) == 0 and sizes == [2]  # nothing left to run: no pool at all


def test_a_cell_is_run_again_when_the_code_that_made_it_changed(short_sequence, tmp_path, capsys, monkeypatch):
    """A tracker edited in place (or another release at the same version number) is another
    run: the identity holds a hash of the code (pipeline.identity.code_identity)."""
    from eas_vo.pipeline import identity

    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original",
        "--backends",
        "chain",
        "--duration",
        "1",
        "--out",
        str(tmp_path / "cmp"),
        "--jobs",
        "1",
        "--quiet",
    ]
    for code, runs in (("A", 1), ("A", 0), ("B", 1)):
        monkeypatch.setattr(identity, "code_identity", lambda packages, code=code: code)
        assert main(argv) == 0
        assert f"1 cells ({runs} run, {1 - runs} already complete" in capsys.readouterr().out


def test_the_code_identity_follows_every_source_file_of_a_plugins_package(tmp_path, monkeypatch):
    from eas_vo.pipeline.identity import code_identity

    package = tmp_path / "eas_vo_probe"
    (package / "inner").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "inner" / "__init__.py").write_text("")
    (package / "inner" / "tracker.py").write_text("STEP = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("eas_vo_probe", "eas_vo_probe.inner"):
        monkeypatch.delitem(sys.modules, name, raising=False)  # (imported below; gone after the test)
    first = code_identity.__wrapped__(("eas_vo_probe",))
    assert code_identity.__wrapped__(("eas_vo_probe",)) == first
    (package / "inner" / "tracker.py").write_text("STEP = 2\n")  # a nested module edited in place
    second = code_identity.__wrapped__(("eas_vo_probe",))
    (package / "inner" / "notes.txt").write_text("not code")
    assert second != first and code_identity.__wrapped__(("eas_vo_probe",)) == second
    assert code_identity.__wrapped__(("eas_vo", "eas_vo_probe")) not in (first, second)


def test_a_cell_is_run_again_when_its_dataset_changed_at_the_same_path(sequence_copy, short_sequence, tmp_path, capsys):
    """Class 3 with the data, not the options, changed: the folder replaced by other content
    under the same path (here the same recording, its frames list cut to 1 s)."""
    out = tmp_path / "cmp"
    argv = [
        "compare",
        "--dataset",
        str(sequence_copy),
        "--frontends",
        "original",
        "--backends",
        "chain",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(argv) == 0
    shutil.rmtree(sequence_copy)
    shutil.copytree(short_sequence, sequence_copy)
    lines = (sequence_copy / "images.txt").read_text().splitlines(keepends=True)
    (sequence_copy / "images.txt").write_text("".join(lines[:20]))
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 cells (1 run, 0 already complete" in capsys.readouterr().out
    (after,) = json.loads((out / "table.json").read_text())
    assert json.loads((out / after["folder"] / "metrics.json").read_text())["frames"] == 20


def test_compare_takes_its_default_tracker_and_backend_from_the_config(short_sequence, tmp_path):
    """`compare --config best` runs best.toml's klt+gtsam, as `run --config best` would."""
    from eas_vo.config import resolve

    out = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                "--dataset",
                str(short_sequence),
                "--frontends",
                "eas",
                "--config",
                "best",
                "--duration",
                "0.5",
                "--out",
                str(out),
                "--jobs",
                "1",
                "--quiet",
            ]
        )
        == 0
    )
    (row,) = json.loads((out / "table.json").read_text())
    run = resolve("best", {"dataset": str(short_sequence)}).run
    assert (row["tracker"], row["backend"]) == (run.tracker, run.backend) == ("klt", "gtsam")


@pytest.mark.parametrize("executor", ["local", "dask"])
def test_any_exception_in_a_cell_is_that_cells_failure_and_the_grid_finishes(
    short_sequence, tmp_path, capsys, monkeypatch, executor
):
    """A frontend that raises a ValueError (a bug, not bad input; with `|` and a newline in its
    message): its cells fail in the table with the type and a request to report it, the
    traceback in the cell's error.txt; every other cell finishes, the table is written, and the
    exit status says a cell failed. Two processes (forked: the patch reaches them), and an
    in-process Dask cluster."""
    from eas_vo.frontends.intensity import HistEqFrontend

    def broken(self, sample):
        raise ValueError("no | image\nat all")

    monkeypatch.setattr(HistEqFrontend, "__call__", broken)
    out = tmp_path / "cmp"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original,histeq",
        "--backends",
        "chain,gtsam",
        "--duration",
        "0.5",
        "--out",
        str(out),
        "--quiet",
        "--jobs",
        "2",
    ]
    if executor == "dask":
        distributed = pytest.importorskip("distributed", reason="the 'distributed' extra is not installed")
        cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None)
        argv += ["--executor", "dask", "--scheduler", cluster.scheduler_address]
    with cluster if executor == "dask" else contextlib.nullcontext():
        assert main(argv) == 1
    captured = capsys.readouterr()
    assert "4 cells (4 run, 0 already complete, 2 failed)" in captured.out
    rows = {(r["frontend"], r["backend"]): r for r in json.loads((out / "table.json").read_text())}
    for backend in ("chain", "gtsam"):
        assert rows[("original", backend)]["status"] == "ok"
        failed = rows[("histeq", backend)]
        assert failed["status"] == "failed" and failed["error"].startswith("ValueError: no | image (a bug")
        assert f"cell {failed['folder']} failed: ValueError: no | image (a bug" in captured.err
        error_txt = (out / failed["folder"] / "error.txt").read_text()
        assert error_txt.startswith(failed["error"] + "\n") and "Traceback" in error_txt and "in broken" in error_txt
    histeq_row = next(line for line in (out / "table.md").read_text().splitlines() if line.startswith("| histeq |"))
    assert histeq_row.count(" | ") == 4 and "ValueError: no \\| image" in histeq_row


def test_a_resume_removes_the_temporaries_of_a_compare_killed_while_writing(one_cell, tmp_path):
    """What `kill -9` leaves while compare writes its figures and tables (temporaries of a
    writer that is gone, this version's and the older pid-less kind) is removed by the resume;
    a live writer's temporary and files that are not compare's own stay."""
    import subprocess

    out, argv, _ = one_cell
    copy = tmp_path / "one"
    shutil.copytree(out, copy)
    gone = subprocess.Popen(["true"])
    gone.wait()
    stale = [f".ape_bars.png.{gone.pid}.k2j3h4ab.tmp", ".ape_time.png.k2j3h4ab.tmp", f".table.json.{gone.pid}.x1y2.tmp"]
    kept = [f".table.md.{os.getpid()}.abcd1234.tmp", f".notes.txt.{gone.pid}.abcd1234.tmp", "ape_bars.png.tmp"]
    for name in stale + kept:
        (copy / name).write_bytes(b"half a file")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(argv[:-4] + [str(copy), "--jobs", "1", "--quiet"]) == 0
    assert [name for name in stale + kept if (copy / name).exists()] == kept


def test_compare_writes_only_into_a_new_empty_or_its_own_folder(one_cell, tmp_path, capsys):
    """A folder holding someone's table.md, or another command's output (a run's), is refused and
    left as it was; compare's own folder is resumed, and a run never replaces it."""
    from helpers import mark_as_eas_vo_output

    out, argv, _ = one_cell
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "table.md").write_text("my notes\n")
    other = tmp_path / "other"
    other.mkdir()
    (other / "metrics.json").write_text("{}\n")
    mark_as_eas_vo_output(other)
    for folder, holds in ((mine, "table.md"), (other, ".eas-vo-output")):
        before = {p.name: p.read_bytes() for p in folder.iterdir()}
        assert main(argv[:-4] + [str(folder), "--jobs", "1", "--quiet"]) == 1
        assert f"--out {folder} holds {holds} and is not an earlier compare's" in capsys.readouterr().err
        assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    assert main(argv[:-4] + [str(copy), "--jobs", "1", "--quiet"]) == 0
    assert "1 cells (0 run, 1 already complete, 0 failed)" in capsys.readouterr().out
    dataset = argv[argv.index("--dataset") + 1]
    assert main(["run", "--dataset", dataset, "--duration", "0.2", "--out", str(copy), "--overwrite", "--quiet"]) == 1
    assert "which eas-vo did not write" in capsys.readouterr().err and (copy / "table.md").exists()
