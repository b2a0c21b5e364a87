"""`eas-vo reproduce table1 | table2` end to end: two simulated sequences served as hdr_boxes
and hdr_poster by a local HTTP server, fetched, run, and tabled beside the paper's figures."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.cli.main import main
from eas_vo.experiments.paper import PAPER_TABLE1, PAPER_TABLE2
from helpers import publish_sequences


@pytest.fixture(scope="module")
def second_sequence(tmp_path_factory):
    from eas_vo.datasets.simulator import SimConfig, simulate

    folder = tmp_path_factory.mktemp("sim") / "second"
    simulate(SimConfig(duration_s=2.0, seed=5), folder)
    return folder


def serve_as_paper_sequences(data_server, boxes, poster, tmp_path, monkeypatch) -> dict:
    """`boxes` and `poster` (ECD folders) served by the loopback server as hdr_boxes and
    hdr_poster, eas-vo pointed at it; the server's hit counts."""
    folder, url, _, hits = data_server
    registry = tmp_path / "registry.txt"
    publish_sequences(folder, {"hdr_boxes": boxes, "hdr_poster": poster}, registry)
    monkeypatch.setenv("EAS_VO_DATA_URL", url)
    monkeypatch.setenv("EAS_VO_DATA_REGISTRY", str(registry))
    monkeypatch.setenv("EAS_VO_DATA_DIR", str(tmp_path / "data"))
    return hits


@pytest.fixture
def paper_site(data_server, short_sequence, second_sequence, tmp_path, monkeypatch):
    return serve_as_paper_sequences(data_server, short_sequence, second_sequence, tmp_path, monkeypatch)


def test_table1_in_one_command_beside_the_papers(paper_site, tmp_path, capsys):
    out = tmp_path / "t1"
    argv = ["reproduce", "table1", "--duration", "1", "--out", str(out), "--jobs", "2", "--quiet"]
    assert main(argv) == 0
    assert paper_site["hdr_boxes.zip"] == 1 and paper_site["hdr_poster.zip"] == 1
    rows = json.loads((out / "table.json").read_text())
    assert len(rows) == 24 and {r["status"] for r in rows} == {"ok"}
    table = (out / "table1.md").read_text()
    smoothed = "klt+gtsam (keyframe_interval=3)"  # the pose graph on klt's keyframe edges, beside the paper's chain
    assert {r["method"] for r in rows} == {"klt+chain", smoothed} and {r["same_as"] for r in rows} == {""}
    for r in rows:
        resolved = (out / r["folder"] / "config.toml").read_text()
        assert f"keyframe_interval = {3 if r['backend'] == 'gtsam' else 0}\n" in resolved
    assert "Configuration: `--config paper`." in table.split("## klt+chain")[1].split("## ")[0]
    assert (
        "Configuration: `--config paper --set tracker.klt.keyframe_interval=3`. The paper's columns are its own "
        "method's (klt+chain)."
    ) in table.split(f"## {smoothed}")[1]
    for method in ("klt+chain", smoothed):
        section = table.split(f"## {method}")[1].split("## ")[0]
        for source in ("original", "histeq", "slice", "ts", "sits", "eas"):
            line = next(x for x in section.splitlines() if x.startswith(f"| {source} |"))
            cells = [c.strip() for c in line.strip("|").split("|")]
            for k, seq in enumerate(("hdr_boxes", "hdr_poster")):
                ours = next(
                    r for r in rows if r["dataset_name"] == seq and r["frontend"] == source and r["method"] == method
                )
                nc, nc_paper, ape, ape_paper, ratio = cells[1 + 5 * k : 6 + 5 * k]
                assert (int(nc_paper), float(ape_paper)) == PAPER_TABLE1[seq][source]
                assert ape == f"{ours['ape_mean_rad']:.3f}" + ("*" if ours["time_offset_estimated"] is False else "")
                assert float(nc) == pytest.approx(ours["nc_mean"], abs=0.5)
                assert float(ratio) == pytest.approx(ours["ape_mean_rad"] / PAPER_TABLE1[seq][source][1], abs=5e-3)
        assert section.count("sources by APE (best first): ours ") == 2
        assert "paper eas < " in section and "Spearman rank correlation" in section
    for seq in ("hdr_boxes", "hdr_poster"):
        for method in ("klt-chain", "klt-gtsam-keyframe_interval=3"):
            assert (out / f"fig3_{seq}_{method}.png").stat().st_size > 10_000
    assert (out / "ape_bars.png").exists() and (out / "hdr_boxes" / "eas_klt_chain" / "metrics.json").exists()
    capsys.readouterr()
    assert main(argv) == 0  # resumable: nothing runs again, nothing is fetched again
    assert "24 cells (0 run, 24 already complete, 0 failed)" in capsys.readouterr().out
    assert paper_site["hdr_boxes.zip"] == 1


def test_table1_marks_a_cell_whose_time_offset_could_not_be_estimated():
    from eas_vo.experiments.gallery import PAPER_ORDER
    from eas_vo.experiments.paper import SEQUENCES
    from eas_vo.experiments.table1 import table1_markdown

    cells = [(seq, source) for seq in SEQUENCES for source in PAPER_ORDER]
    rows = [
        {
            "dataset_name": seq,
            "method": "klt+chain",
            "settings": (),
            "frontend": source,
            "status": "ok",
            "nc_mean": 100.0,
            "ape_mean_rad": 0.05 + 0.01 * k,
            "time_offset_estimated": True,
            "same_as": "",
        }
        for k, (seq, source) in enumerate(cells)
    ]
    table = table1_markdown(rows, "paper", 25.0)
    assert "* |" not in table and "could not be estimated" not in table
    rows[3]["time_offset_estimated"] = False
    table = table1_markdown(rows, "paper", 25.0)
    assert table.count("* |") == 1 and "| 0.080* |" in table and "could not be estimated for this cell" in table


def test_compares_default_methods_are_the_papers_chain_and_the_smoothed_pose_graph():
    from eas_vo.experiments.cells import Method
    from eas_vo.experiments.paper import PAPER, SMOOTHED, default_methods

    assert default_methods("klt", "chain") == [PAPER, SMOOTHED] and SMOOTHED.settings == (
        ("tracker.klt.keyframe_interval", "3"),
    )
    assert default_methods("klt", "gtsam") == [Method("klt", "gtsam")]  # a config's own method: as it is configured


def test_table1s_grid_is_the_papers_chain_beside_the_smoothed_pose_graph():
    from eas_vo.experiments.gallery import PAPER_ORDER
    from eas_vo.experiments.paper import PAPER, SEQUENCES, SMOOTHED, paper_cells, table1_methods
    from eas_vo.experiments.table1 import table1_markdown

    assert table1_methods(("chain", "gtsam")) == [PAPER, SMOOTHED]
    cells = paper_cells(PAPER_ORDER, table1_methods(("chain", "gtsam")))
    assert {(c.dataset_name, c.method) for c in cells} == {(s, m) for s in SEQUENCES for m in (PAPER, SMOOTHED)}
    assert sum(c.folder.endswith("_klt_gtsam_keyframe_interval-3") for c in cells) == 2 * len(PAPER_ORDER)
    rows = [
        {
            "dataset_name": seq,
            "method": m,
            "settings": (),
            "frontend": source,
            "status": "ok",
            "nc_mean": 100.0,
            "ape_mean_rad": 0.1 + 0.01 * k,
            "time_offset_estimated": True,
            "same_as": "klt+chain" if m == "klt+gtsam" else "",
        }
        for seq in SEQUENCES
        for m in ("klt+chain", "klt+gtsam")
        for k, source in enumerate(PAPER_ORDER)
    ]
    table = table1_markdown(rows, "paper", 25.0)  # a pose graph on consecutive edges alone: said to be the chain
    assert (
        table.count("Its trajectories are klt+chain's") == 1
        and "## klt+gtsam\n\nConfiguration: `--config paper`. Its" in table
    )


@pytest.fixture
def without_slam_extra(monkeypatch):
    """As if pyorbslam3 were not installed: reproduce table2's path without ORB-SLAM3."""
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pyorbslam3" else real(name, *a))


def test_table2_orb_statistics_and_a_slam_trajectorys_ape(paper_site, short_sequence, tmp_path, without_slam_extra):
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum
    from eas_vo.registry import open_dataset

    gt = open_dataset(str(short_sequence)).ground_truth
    keyframes = np.arange(0, len(gt.t), 10)
    R_a = Rotation.from_rotvec([0.2, 0.1, -0.3]).as_matrix()
    estimate = tmp_path / "KeyFrameTrajectory.txt"
    estimate.write_text(
        format_tum(
            gt.t[keyframes], 0.5 * gt.p_w_c[keyframes] @ R_a.T + 1.0, R_a @ matrices_from_quats(gt.q_w_c[keyframes])
        )
    )
    out = tmp_path / "t2"
    assert (
        main(
            [
                "reproduce",
                "table2",
                "--duration",
                "1",
                "--out",
                str(out),
                "--jobs",
                "2",
                "--quiet",
                "--estimate",
                f"hdr_boxes:eas={estimate}",
            ]
        )
        == 0
    )
    table = (out / "table2.md").read_text()
    lines = {
        line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")[1:]]
        for line in table.splitlines()
        if line.startswith("| ") and "(" in line.split("|")[1]
    }
    slam = json.loads((out / "slam" / "hdr_boxes_eas" / "metrics.json").read_text())
    assert slam["scale"] == pytest.approx(2.0, rel=1e-6) and slam["ape_trans_mean_m"] < 1e-6
    assert (
        lines["average APE [m] (ours)"][1] == "0.000"
        and "no ORB-SLAM2 trajectory given" in lines["average APE [m] (ours)"][0]
    )
    assert lines["average APE [m] (paper)"] == ["0.021", "0.029", "0.049", "0.058"]
    rows = {(r["dataset_name"], r["frontend"]): r for r in json.loads((out / "table.json").read_text())}
    ours = [rows[(s, f)]["orb_keypoints_mean"] for s in ("hdr_boxes", "hdr_poster") for f in ("original", "eas")]
    assert [float(v) for v in lines["ORB features (ours)"]] == pytest.approx(ours, abs=0.5)
    assert lines["matches (paper)"] == [
        str(PAPER_TABLE2[s][f]["matches"]) for s in ("hdr_boxes", "hdr_poster") for f in ("original", "eas")
    ]


@pytest.mark.parametrize(
    "estimate, says",
    [
        ("hdr_boxes:ts={tmp}/x.txt", "the Table 2 asked for has hdr_boxes, hdr_poster x original, eas"),
        ("hdr_boxes:eas={tmp}/missing.txt", "missing.txt: cannot read"),
        ("hdr_poster:original={tmp}/empty.txt", "empty.txt: holds no pose"),
    ],
)
def test_a_bad_estimate_is_refused_before_any_work(paper_site, tmp_path, capsys, estimate, says):
    (tmp_path / "empty.txt").write_text("# nothing\n")
    out = tmp_path / "t2"
    assert main(["reproduce", "table2", "--out", str(out), "--estimate", estimate.replace("{tmp}", str(tmp_path))]) == 1
    assert says in capsys.readouterr().err
    assert paper_site["hdr_boxes.zip"] == 0 and not out.exists()


@pytest.mark.parametrize(
    "argv, says",
    [
        (["table1", "--config", "nosuch"], "nosuch"),
        (["table1", "--backends", "chain,nosuch"], "nosuch"),
        (["table2", "--config", "nosuch"], "nosuch"),
    ],
)
def test_a_bad_configuration_is_refused_before_any_download(paper_site, tmp_path, capsys, argv, says):
    out = tmp_path / "out"
    assert main(["reproduce", *argv, "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err
    assert paper_site["hdr_boxes.zip"] == 0 and paper_site["hdr_poster.zip"] == 0 and not out.exists()


def test_an_estimate_given_twice_is_refused(paper_site, short_sequence, tmp_path, capsys):
    (tmp_path / "a.txt").write_text("1 0 0 0 0 0 0 1\n")
    estimate = f"hdr_boxes:eas={tmp_path / 'a.txt'}"
    assert (
        main(["reproduce", "table2", "--out", str(tmp_path / "t2"), "--estimate", estimate, "--estimate", estimate])
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--estimate hdr_boxes:eas given twice" in err
    assert paper_site["hdr_boxes.zip"] == 0


def test_an_estimate_the_ground_truth_cannot_score_is_refused_before_the_cells_run(
    paper_site, short_sequence, tmp_path, capsys
):
    """A well-formed TUM file of two poses (sim3 needs three): refused once the ground truth is
    there, before any cell ran."""
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum
    from eas_vo.registry import open_dataset

    gt = open_dataset(str(short_sequence)).ground_truth
    estimate = tmp_path / "KeyFrameTrajectory.txt"
    estimate.write_text(format_tum(gt.t[:2], gt.p_w_c[:2], matrices_from_quats(gt.q_w_c[:2])))
    out = tmp_path / "t2"
    assert (
        main(
            [
                "reproduce",
                "table2",
                "--duration",
                "1",
                "--out",
                str(out),
                "--quiet",
                "--estimate",
                f"hdr_boxes:eas={estimate}",
            ]
        )
        == 1
    )
    (error,) = [line for line in capsys.readouterr().err.splitlines() if "error" in line]  # after the fetch's lines
    assert "KeyFrameTrajectory.txt" in error and "sim3 alignment needs at least 3" in error
    assert not (out / "hdr_boxes").exists() and not (out / "table2.md").exists()


@pytest.mark.parametrize("held", ["config", "table", "data"])
def test_an_out_that_is_not_reproduces_own_is_refused_before_any_download(
    paper_site, tmp_path, capsys, monkeypatch, held
):
    """An --out holding the --config, someone's table2.md or the data folder sequences are
    fetched into: refused in one line, nothing fetched, nothing in it changed."""
    import shutil
    from pathlib import Path

    import eas_vo.configs

    out = tmp_path / "mine"
    out.mkdir()
    config = out / "paper.toml"
    if held == "config":
        shutil.copy(Path(eas_vo.configs.__file__).parent / "paper.toml", config)
    elif held == "table":
        (out / "table2.md").write_text("my notes\n")
    else:
        (out / "data").mkdir()
        monkeypatch.setenv("EAS_VO_DATA_DIR", str(out / "data"))
    before = {p: p.read_bytes() if p.is_file() else None for p in out.rglob("*")}
    argv = ["reproduce", "table2", "--duration", "0.3", "--out", str(out), "--jobs", "1", "--quiet"]
    assert main(argv + (["--config", str(config)] if held == "config" else [])) == 1
    err = capsys.readouterr().err
    says = {
        "config": f"holds the --config {config}",
        "table": "holds table2.md and is not an earlier compare's",
        "data": f"holds the data folder {out / 'data'}",
    }[held]
    assert err.count("\n") == 1 and says in err, err
    assert paper_site["hdr_boxes.zip"] == 0 and paper_site["hdr_poster.zip"] == 0
    assert {p: p.read_bytes() if p.is_file() else None for p in out.rglob("*")} == before


@pytest.fixture
def walk_site(data_server, tmp_path, monkeypatch):
    """The translating walk (synthetic:walk_short, which ORB-SLAM3 initialises on) served as
    both hdr_boxes and hdr_poster: the table's cells, not the scenes, are under test."""
    from eas_vo.datasets.synthetic import sequence_folder

    walk = sequence_folder("walk_short", progress=False)
    return serve_as_paper_sequences(data_server, walk, walk, tmp_path, monkeypatch)


def test_table2_runs_orbslam3_on_each_cell_beside_the_papers(walk_site, walk_vocabulary, tmp_path):
    """With the slam extra: ORB-SLAM3 on original and EAS images of both sequences, the median
    keyframe APE of its runs in the table beside the paper's, each cell's runs kept, Fig. 4
    drawn; the same command again runs nothing."""
    pytest.importorskip("pyorbslam3", reason="the slam extra (pyorbslam3) is not installed")
    out = tmp_path / "t2"
    argv = [
        "reproduce",
        "table2",
        "--duration",
        "5",
        "--out",
        str(out),
        "--jobs",
        "2",
        "--quiet",
        "--runs",
        "1",
        "--vocabulary",
        str(walk_vocabulary),
    ]
    assert main(argv) == 0
    report = json.loads((out / "table2.json").read_text())["slam"]
    table = (out / "table2.md").read_text()
    ape_row = next(line for line in table.splitlines() if line.startswith("| average APE [m] (ours)"))
    cells = [c.strip() for c in ape_row.strip("|").split("|")[1:]]
    for k, (seq, source) in enumerate((s, f) for s in ("hdr_boxes", "hdr_poster") for f in ("original", "eas")):
        m = report[f"{seq}:{source}"]
        assert m["runs"] == 1 and (out / "slam" / f"{seq}_{source}" / "run_1" / "frames.csv").is_file()
        if m["ape_trans_mean_m"] is None:
            assert cells[k].startswith("no run tracked")
        else:
            assert cells[k].startswith(f"{m['ape_trans_mean_m']:.3f} (")
    assert report["hdr_boxes:original"]["ape_trans_mean_m"] is not None  # the walk's original frames: it tracks
    assert "ORB-SLAM3 (monocular, pyorbslam3)" in table
    eq3 = next(line for line in table.splitlines() if line.startswith("| rotation APE, Eq. 3 [rad] (ORB-SLAM3"))
    median = report["hdr_boxes:original"]["rotation_eq3.ape_mean_rad"]["median"]
    assert eq3.split("|")[2].strip() == f"{median:.3f}"
    assert "| rotation APE, Eq. 3 [rad] (eas-vo --config paper, klt+chain, every frame) |" in table
    best_row = next(
        line
        for line in table.splitlines()
        if line.startswith("| rotation APE, Eq. 3 [rad] (eas-vo --config best, klt+gtsam, every frame) |")
    )
    assert {p.parent.name for p in (out / "best").rglob("metrics.json")} == {"original_klt_gtsam", "eas_klt_gtsam"}
    best_metrics = json.loads(next((out / "best").rglob("metrics.json")).read_text())
    assert f"{best_metrics['ape_mean_rad']:.3f}" in [cell.strip() for cell in best_row.split("|")[2:]]
    assert (out / "fig4_hdr_boxes.png").stat().st_size > 0
    before = (out / "slam" / "hdr_boxes_eas" / "summary.json").stat().st_mtime_ns
    assert main(argv) == 0
    assert (out / "slam" / "hdr_boxes_eas" / "summary.json").stat().st_mtime_ns == before


def test_a_table2_cell_reruns_slam_runs_made_under_another_protocol(tmp_path, monkeypatch):
    """A cell's summary.json is reused only when its runs were paced and judged as slam runs
    now are (slam.scores.PROTOCOL): an older folder, whose statuses followed another rule, reruns."""
    from eas_vo.experiments import grid, table2
    from eas_vo.experiments.cells import Cell
    from eas_vo.slam import run as slam_run
    from eas_vo.slam import scores

    calls = []

    def run_slam(config, folder, vocabulary, runs, progress, replace):
        calls.append(folder)
        return {
            "runs": runs,
            "vocabulary": vocabulary,
            "protocol": scores.PROTOCOL,
            "crashed": [],
            "ape_keyframes.ape_trans_mean_m": {"median": 0.02},
        }

    monkeypatch.setattr(slam_run, "run_slam", run_slam)
    monkeypatch.setattr(grid, "cell_config", lambda *a: None)
    folder = tmp_path / "slam" / "hdr_boxes_eas"
    folder.mkdir(parents=True)
    old = {"runs": 2, "vocabulary": "voc.txt", "statuses": {"ok": 2}, "ape_keyframes.ape_trans_mean_m": {"median": 0.5}}
    (folder / "summary.json").write_text(json.dumps(old))
    cell = Cell("ecd:hdr_boxes", "eas", "klt", "chain", (), "hdr_boxes")
    got = table2._slam_cell(cell, "paper", {}, folder, "voc.txt", 2, False)
    assert calls == [folder] and got["ape_trans_mean_m"] == 0.02
    (folder / "summary.json").write_text(json.dumps({**old, "protocol": scores.PROTOCOL}))
    assert table2._slam_cell(cell, "paper", {}, folder, "voc.txt", 2, False)["ape_trans_mean_m"] == 0.5
    assert calls == [folder]


@pytest.mark.parametrize("where", ["environment", "data_folder"])
def test_table2s_vocabulary_is_checked_whole_and_a_broken_one_never_replaced(tmp_path, monkeypatch, where):
    """A vocabulary in $PYORBSLAM3_VOCAB or the data folder that is cut short is refused naming
    its line: neither handed to ORB-SLAM3 nor swapped for a download."""
    from eas_vo.errors import DataError
    from eas_vo.experiments import table2
    from eas_vo.slam import orbvoc
    from eas_vo.slam.vocabulary import train

    rng = np.random.default_rng(2)
    text = train([rng.integers(0, 256, (60, 32), dtype=np.uint8) for _ in range(2)], k=3, levels=2, seed=0).text()
    data = tmp_path / "data"
    data.mkdir()
    path = tmp_path / "mine.txt" if where == "environment" else data / "ORBvoc.txt"
    path.write_text(text[: len(text) // 2])  # cut inside a line
    monkeypatch.setenv("EAS_VO_DATA_DIR", str(data))
    if where == "environment":
        monkeypatch.setenv("PYORBSLAM3_VOCAB", str(path))
    else:
        monkeypatch.delenv("PYORBSLAM3_VOCAB", raising=False)
    monkeypatch.setattr(orbvoc, "fetch_orb_vocabulary", lambda **kw: pytest.fail("a download replaced the vocabulary"))
    with pytest.raises(
        DataError, match=rf"^{path}:{text[: len(text) // 2].count(chr(10)) + 1}: expected 'parent is_leaf'"
    ):
        table2._vocabulary(False)


def test_table2s_rows_say_the_configuration_and_method_their_cells_ran(tmp_path, monkeypatch):
    """Table 2's rotation rows (ORB-SLAM3 faked, every grid recorded instead of run): the
    configuration asked for with the paper's klt+chain, and configs/best.toml with its own
    tracker and backend, as `--config best` runs it; each row's label names both."""
    import importlib.util

    from eas_vo import config
    from eas_vo.experiments import grid, table2

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: object() if name == "pyorbslam3" else real(name, *a)
    )
    grids = []

    def run_experiment(cells, out, config_file, assignments, overrides, jobs, progress):
        grids.append((config_file, {(c.tracker, c.backend) for c in cells}))
        return (
            [
                {
                    "dataset_name": c.dataset_name,
                    "frontend": c.frontend,
                    "method": c.method.label,
                    "status": "ok",
                    "folder": c.folder,
                    "ape_mean_rad": 0.1 * len(grids),
                    "orb_keypoints_mean": 1.0,
                    "orb_matches_mean": 1.0,
                }
                for c in cells
            ],
            len(cells),
        )

    monkeypatch.setattr(grid, "run_experiment", run_experiment)
    monkeypatch.setattr(table2, "fetch_sequences", lambda progress: None)
    monkeypatch.setattr(table2, "check_cells", lambda *a: None)
    monkeypatch.setattr(table2, "_vocabulary", lambda progress: tmp_path / "voc.txt")
    monkeypatch.setattr(table2, "_slam_cell", lambda *a: {"ape_trans_mean_m": None, "statuses": {}})
    monkeypatch.setattr(table2, "_keyframe_figures", lambda *a: None)
    best = config.run_section("best")
    assert (best.tracker, best.backend) == ("klt", "gtsam")  # what `--config best` runs
    rows, n_run, markdown = table2.table2(tmp_path / "out", {}, config="paper")
    assert grids == [("paper", {("klt", "chain")}), ("best", {("klt", "gtsam")})]
    assert len(rows) == n_run == 8  # every cell run is reported: 2 sequences x 2 sources, in both grids
    assert {r["folder"].split("/")[0] for r in rows if r["method"] == "klt+gtsam"} == {"best"}
    rows = [line for line in markdown.splitlines() if line.startswith("| rotation APE, Eq. 3 [rad] (eas-vo")]
    assert [row.split("|")[1].strip() for row in rows] == [
        "rotation APE, Eq. 3 [rad] (eas-vo --config paper, klt+chain, every frame)",
        "rotation APE, Eq. 3 [rad] (eas-vo --config best, klt+gtsam, every frame)",
    ]
    assert [row.split("|")[2].strip() for row in rows] == ["0.100", "0.200"]
    assert markdown.startswith("# Table 2: ours (`--config paper`, whole sequences)")


def test_offline_reproduce_names_the_offline_route_and_leaves_no_folder(tmp_path, capsys, monkeypatch):
    """No server (the suite's EAS_VO_DATA_URL points at a closed loopback port): one line naming
    EAS_VO_DATA_DIR and EAS_VO_DATA_URL, exit status 1, and no --out folder left behind."""
    monkeypatch.setenv("EAS_VO_DATA_DIR", str(tmp_path / "data"))
    out = tmp_path / "results" / "table1"
    assert main(["reproduce", "table1", "--out", str(out), "--quiet"]) == 1
    (err,) = capsys.readouterr().err.splitlines()
    assert "cannot reach the server" in err and "EAS_VO_DATA_DIR" in err and "EAS_VO_DATA_URL" in err
    assert not out.exists()
