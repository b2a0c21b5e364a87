"""The paper's Table 2 on its own data (`eas-vo reproduce table2`): ORB features and matches of
the sources and the keyframe APE of monocular SLAM on them (ORB-SLAM3 runs, or ORB-SLAM2
trajectories given), beside the published figures, and Fig. 4-style keyframe plots."""

from __future__ import annotations

from pathlib import Path

from eas_vo.errors import DataError, EasVoError
from eas_vo.experiments import grid
from eas_vo.experiments.cells import Cell, Method
from eas_vo.experiments.paper import (
    PAPER,
    PAPER_TABLE2,
    PAPER_TABLE2_DURATION_S,
    SEQUENCES,
    SPECS,
    TABLE2_SOURCES,
    check_cells,
    fetch_sequences,
    paper_cells,
    run_overrides,
)
from eas_vo.io.atomic import atomic_path, json_text, write_text_atomic
from eas_vo.io.text import figure_text


def table2(
    out: Path,
    estimates: dict[tuple[str, str], str],
    duration_s: float | None = PAPER_TABLE2_DURATION_S,
    config: str = "paper",
    jobs: int = 1,
    progress: bool = False,
    frontends=TABLE2_SOURCES,
    runs: int = 5,
    vocabulary: str | None = None,
) -> tuple[list[dict], int, str]:
    """ORB features and matches per image (each of `frontends`, both sequences) and the keyframe
    APE after Sim(3) alignment of monocular SLAM on the same images: for {(sequence, source):
    file} given, that ORB-SLAM2 trajectory scored (OUT/slam/SEQUENCE_SOURCE); for the others,
    with the slam extra installed, `runs` runs of ORB-SLAM3 (eas-vo slam, into the same
    folders; a folder holding that many runs with this vocabulary is kept: resumable).
    Writes table2.md beside the paper's, table2.json and the Fig. 4 panels. Returns (the rows
    of every cell run: with ORB-SLAM3, best.toml's too, their folders under `best/`; cells run;
    table2 markdown)."""
    import importlib.util

    from eas_vo.experiments.external import evaluate_estimate
    from eas_vo.io.tum import read_tum

    for (seq, source), path in estimates.items():
        if seq not in SEQUENCES or source not in frontends:
            raise EasVoError(
                f"--estimate {seq}:{source}: the Table 2 asked for has {', '.join(SEQUENCES)} x {', '.join(frontends)}"
            )
        read_tum(path)  # a missing or malformed file is an error before any download
    with_slam = importlib.util.find_spec("pyorbslam3") is not None
    if with_slam and vocabulary:
        from eas_vo.slam.process import find_vocabulary

        vocabulary = str(find_vocabulary(vocabulary))
    cells, overrides = paper_cells(frontends, [PAPER]), run_overrides(duration_s, orb=True)
    check_cells(cells, config, overrides, out)
    fetch_sequences(progress)
    # scored before the cells run: an estimate the ground truth cannot score is an error before that work
    slam = {
        key: evaluate_estimate(
            SPECS[key[0]],
            path,
            "sim3",
            0.01,
            out / "slam" / f"{key[0]}_{key[1]}",
            label=f"{key[0]} {key[1]}",
            replace=True,
        )
        for key, path in estimates.items()
    }
    rows, n_run = grid.run_experiment(cells, out, config, [], overrides, jobs, progress)
    best_rows = []
    if (
        with_slam
    ):  # eas-vo's most accurate configuration on the same images, as `--config best` runs it, for the rotation rows
        best_rows, n_best = grid.run_experiment(
            paper_cells(frontends, [best_method()]),
            out / "best",
            "best",
            [],
            run_overrides(duration_s, orb=False),
            jobs,
            progress,
        )
        best_rows = [{**r, "folder": f"best/{r['folder']}"} for r in best_rows]  # (relative to `out`, as the others)
        n_run += n_best
        vocabulary = vocabulary or str(_vocabulary(progress))
        for cell in cells:
            key = (cell.dataset_name, cell.frontend)
            if key not in slam:
                slam[key] = _slam_cell(
                    cell, config, overrides, out / "slam" / f"{key[0]}_{key[1]}", vocabulary, runs, progress
                )
        _keyframe_figures(out, cells, slam)
    markdown = table2_markdown(rows, slam, duration_s, frontends, with_slam, best_rows, config)
    write_text_atomic(out / "table2.md", markdown)
    write_text_atomic(
        out / "table2.json",
        json_text(
            {
                "paper": PAPER_TABLE2,
                "orb": rows,
                "config": config,
                "best": best_rows,
                "slam": {f"{s}:{f}": m for (s, f), m in slam.items()},
            }
        ),
    )
    return rows + best_rows, n_run, markdown


def best_method() -> Method:
    """configs/best.toml's tracker and backend, as `--config best` runs them."""
    from eas_vo.config import run_section

    run = run_section("best")
    return Method(run.tracker, run.backend)


def _vocabulary(progress: bool) -> Path:
    """The vocabulary ORB-SLAM3 loads: $PYORBSLAM3_VOCAB or the data folder's ORBvoc.txt,
    fetched first if neither is there; checked whole either way (slam.run.find_vocabulary). A
    broken one is an error, never replaced by another."""
    from eas_vo.slam.orbvoc import fetch_orb_vocabulary
    from eas_vo.slam.process import find_vocabulary

    try:
        return find_vocabulary(None)
    except DataError:
        raise
    except EasVoError:  # none there
        return find_vocabulary(str(fetch_orb_vocabulary(progress=progress)))


def _slam_cell(
    cell: Cell, config: str, overrides: dict, folder: Path, vocabulary: str, runs: int, progress: bool
) -> dict:
    """`eas-vo slam` on one cell (its summary.json reused when it holds `runs` runs with
    `vocabulary` made under slam.scores.PROTOCOL); the summary with its median keyframe APE as
    `ape_trans_mean_m` (None when no run tracked and scored)."""
    import json

    from eas_vo.slam.run import run_slam
    from eas_vo.slam.scores import PROTOCOL

    summary_path = folder / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    if summary.get("runs") != runs or summary.get("vocabulary") != vocabulary or summary.get("protocol") != PROTOCOL:
        summary = run_slam(
            grid.cell_config(cell, config, [], overrides), folder, vocabulary, runs, progress, replace=True
        )
        summary.pop("crashed")
    median = (summary.get("ape_keyframes.ape_trans_mean_m") or {}).get("median")
    return {**summary, "ape_trans_mean_m": median, "folder": str(folder)}


def _keyframe_figures(out: Path, cells: list[Cell], slam: dict) -> None:
    """fig4_SEQUENCE.png: the paper's Fig. 4, a column per source: the keyframe positions of the
    run with the median keyframe APE, Sim(3)-aligned, per axis over ground truth, and each
    keyframe's APE."""
    from eas_vo.io.tum import read_tum
    from eas_vo.plots import plot_keyframes
    from eas_vo.registry import open_dataset

    panels: dict = {}
    for cell in cells:
        m = slam.get((cell.dataset_name, cell.frontend), {})
        scored = [r for r in m.get("per_run", []) if "ape_trans_mean_m" in r.get("ape_keyframes", {})]
        if not scored:
            continue
        run = sorted(scored, key=lambda r: r["ape_keyframes"]["ape_trans_mean_m"])[(len(scored) - 1) // 2]
        folder = Path(m["folder"]) / f"run_{run['run']}"
        keyframes = read_tum(folder / "keyframes_aligned.tum", ordered=False)
        t, p = keyframes.t, keyframes.p_w_c
        gt = open_dataset(SPECS[cell.dataset_name]).ground_truth
        label = f"{cell.frontend} (run {run['run']}, APE {run['ape_keyframes']['ape_trans_mean_m']:.3f} m)"
        panels.setdefault(cell.dataset_name, []).append((label, t, p, gt))
    for seq, figure_panels in panels.items():
        with atomic_path(out / f"fig4_{seq}.png") as tmp:
            plot_keyframes(
                tmp, figure_panels, title=f"{seq}: ORB-SLAM3 keyframes (Sim(3)-aligned, red) over ground truth"
            )


def table2_markdown(
    rows: list[dict],
    slam: dict,
    duration_s: float | None,
    frontends=TABLE2_SOURCES,
    with_slam: bool = False,
    best_rows: list[dict] = (),
    config: str = "paper",
) -> str:
    """The paper's Table 2 layout, each of our figures followed by the paper's (a source the
    paper has not: -); with ORB-SLAM3, its rotation scored by Eq. 3 beside eas-vo's on the same
    images: `rows` (`config` with the paper's method) and `best_rows` (configs/best.toml's own
    method), each row labelled with the configuration and the tracker+backend its cells ran."""
    from eas_vo.slam.scores import MIN_TRACKED_FRACTION

    by_key = {(r["dataset_name"], r["frontend"]): r for r in rows}
    columns = [(seq, source) for seq in SEQUENCES for source in frontends]
    head = ["", *[f"{seq} {source}" for seq, source in columns]]
    window = f"first {duration_s:g} s" if duration_s else "whole sequences"
    lines = [
        f"# Table 2: ours (`--config {config}`, {window}) beside the paper's",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    missing = "- (no ORB-SLAM2 trajectory given; ORB-SLAM3 runs with pip install 'eas-vo[slam]')"

    def ours(seq, source, key, fmt):
        if key == "ape_m":
            m = slam.get((seq, source))
            if not m:
                return missing
            if m.get("ape_trans_mean_m") is None:
                return "no run tracked (" + ", ".join(f"{n} {s}" for s, n in m.get("statuses", {}).items()) + ")"
            runs = f" ({m['ape_keyframes.ape_trans_mean_m']['n']}/{m['runs']} runs)" if "runs" in m else ""
            return figure_text(m["ape_trans_mean_m"], 3) + runs
        r = by_key.get((seq, source))
        return f"{r[key]:{fmt}}" if r and r["status"] == "ok" and r[key] is not None else "-"

    def paper(seq, source, key, fmt):
        value = PAPER_TABLE2[seq].get(source, {}).get(key)
        return f"{value:{fmt}}" if value is not None else "-"

    for label, key, row_key, fmt in (
        ("average APE [m]", "ape_m", "ape_m", ".3f"),
        ("ORB features", "orb_keypoints_mean", "features", ".0f"),
        ("matches", "orb_matches_mean", "matches", ".0f"),
    ):
        lines.append("| " + " | ".join([f"{label} (ours)", *[ours(s, f, key, fmt) for s, f in columns]]) + " |")
        lines.append("| " + " | ".join([f"{label} (paper)", *[paper(s, f, row_key, fmt) for s, f in columns]]) + " |")
    if with_slam:  # a 6-DoF system beside the 3-DoF one on rotation, on the same images

        def eq3(seq, source):
            m = (slam.get((seq, source)) or {}).get("rotation_eq3.ape_mean_rad")
            return f"{m['median']:.3f}" if m else "-"

        def ours_eq3(runs, seq, source):
            r = runs.get((seq, source))
            return f"{r['ape_mean_rad']:.3f}" if r and r["status"] == "ok" and r["ape_mean_rad"] is not None else "-"

        lines.append(
            "| "
            + " | ".join(["rotation APE, Eq. 3 [rad] (ORB-SLAM3, tracked frames)", *[eq3(s, f) for s, f in columns]])
            + " |"
        )
        for label_config, runs in ((config, rows), ("best", best_rows)):
            for method in dict.fromkeys(r["method"] for r in runs):  # the label of what the cells ran
                ran = {(r["dataset_name"], r["frontend"]): r for r in runs if r["method"] == method}
                label = f"rotation APE, Eq. 3 [rad] (eas-vo --config {label_config}, {method}, every frame)"
                lines.append("| " + " | ".join([label, *[ours_eq3(ran, s, f) for s, f in columns]]) + " |")
    system = (
        f"ORB-SLAM3 (monocular, pyorbslam3): the median over its runs whose status is ok (from its first "
        f"initialisation on it tracked at least {MIN_TRACKED_FRACTION:.0%} of the frames, the last one among them; "
        "runs scored / runs), an --estimate's ORB-SLAM2 keyframes as given"
        if with_slam
        else "ORB-SLAM2"
    )
    lines += [
        "",
        f"APE: {system}; keyframes after Sim(3) Umeyama alignment (evo_ape -as). ORB features and matches: "
        "per image and matched (cross-checked Hamming) per adjacent pair, OpenCV ORB with ORB-SLAM2's settings "
        "(1000 features, scale 1.2, 8 levels, FAST 20) but not its grid-bucketed extractor (eas-vo compare --orb).",
        "",
    ]
    return "\n".join(lines)
