"""A grid's results: a row a cell, the Table 1 layout in Markdown, CSV and JSON, which methods
gave the same trajectories, and the figures (APE bars, APE over time, sweeps)."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from eas_vo.errors import EasVoError
from eas_vo.experiments.cells import Cell
from eas_vo.io.atomic import json_text, write_text_atomic
from eas_vo.io.text import markdown_cell, slug

#: The files compare writes in its output folder (write_tables, write_figures).
OUTPUT_FILES = ("table.md", "table.csv", "table.json", "ape_bars.png", "ape_time.png", "ape_sweep.png")


def write_figures(out: Path, cells: list[Cell], rows: list[dict]) -> None:
    """ape_bars.png (APE and NC per source), ape_time.png (APE over time of each finished cell)
    and, for a grid swept over one numeric key, ape_sweep.png; a method whose results are an
    earlier one's (row `same_as`) drawn once, under both names; a frontend in one colour throughout."""
    from eas_vo.evaluation.ape import tum_rotation_errors
    from eas_vo.experiments.gallery import PAPER_COLOURS
    from eas_vo.io.atomic import atomic_path
    from eas_vo.plots import frontend_colours, plot_ape_bars, plot_ape_time, plot_sweep

    colours = frontend_colours((c.frontend for c in cells), PAPER_COLOURS)  # every figure the same
    equal = equal_methods(rows)
    drawn = [(cell, row) for cell, row in zip(cells, rows) if not row["same_as"]]
    with atomic_path(out / "ape_bars.png") as tmp:
        plot_ape_bars(tmp, [row for _, row in drawn], equal, colours)
    series = {}
    for cell, row in drawn:
        if row["status"] == "ok":
            curve = tum_rotation_errors(out / cell.folder / "trajectory.tum", out / cell.folder / "groundtruth.tum")
            if curve is not None:
                series[(cell.dataset, row["method"], cell.frontend, row["sweep"])] = curve
    if series:
        with atomic_path(out / "ape_time.png") as tmp:
            plot_ape_time(tmp, series, equal, colours)
    swept = sweep_curves(cells, rows)
    if swept is not None and swept[1]:
        with atomic_path(out / "ape_sweep.png") as tmp:
            plot_sweep(tmp, *swept, colours)


def table_rows(cells: list[Cell], results: dict) -> list[dict]:
    """One row per cell: what it ran (`method` = tracker+backend, a table column) and its figures."""
    return [
        {
            **asdict(cell),
            "method": cell.method.label,
            "sweep": cell.sweep_label,
            "folder": cell.folder,
            "status": results.get(cell, {}).get("status", "not run"),
            "error": results.get(cell, {}).get("error", ""),
            "nc_mean": results.get(cell, {}).get("nc_mean"),
            "ape_mean_rad": results.get(cell, {}).get("ape_mean_rad"),
            **{key: results.get(cell, {}).get(key) for key in MOTION_KEYS},
            "time_offset_estimated": results.get(cell, {}).get("time_offset_estimated"),
            "orb_keypoints_mean": results.get(cell, {}).get("orb_keypoints_mean"),
            "orb_matches_mean": results.get(cell, {}).get("orb_matches_mean"),
            "data_warnings": results.get(cell, {}).get("data_warnings", []),
            "same_as": "",
        }
        for cell in cells
    ]


def same_trajectory(a: Path, b: Path, tol: float = 1e-9) -> bool:
    """Whether two TUM trajectories hold the same timestamps and the same rotations to `tol`
    in every quaternion component (q and -q alike; 1e-9 is about 2e-9 rad, far above the
    files' 12 decimals); False if either is unreadable."""
    from eas_vo.io.tum import read_tum

    try:
        poses_a, poses_b = read_tum(a, ordered=False), read_tum(b, ordered=False)
    except EasVoError:
        return False
    t_a, q_a, t_b, q_b = poses_a.t, poses_a.q_w_c, poses_b.t, poses_b.q_w_c
    if t_a.shape != t_b.shape or not np.array_equal(t_a, t_b):
        return False
    gap = np.minimum(np.abs(q_a - q_b).max(axis=1), np.abs(q_a + q_b).max(axis=1))
    return bool(np.all(gap <= tol))


def mark_identical(out_root: Path, cells: list[Cell], rows: list[dict]) -> list[dict]:
    """`rows` (table_rows of `cells`) with `same_as` set to the label of the first earlier method
    of the same dataset whose results are this method's: the same cells (source, sweep point),
    every one finished in both with the same average NC and the same trajectory
    (same_trajectory), as a pose graph fed only the consecutive edges a chain multiplies gives;
    "" where there is none (a failed cell proves nothing)."""
    columns: dict = {}  # (dataset, method) -> {(frontend, sweep): (nc, trajectory file) or None if not finished}
    for cell, row in zip(cells, rows):
        columns.setdefault((cell.dataset, row["method"]), {})[(cell.frontend, row["sweep"])] = (
            (row["nc_mean"], out_root / cell.folder / "trajectory.tum") if row["status"] == "ok" else None
        )

    def same(a: dict, b: dict) -> bool:
        return a.keys() == b.keys() and all(
            a[k] is not None and b[k] is not None and a[k][0] == b[k][0] and same_trajectory(a[k][1], b[k][1])
            for k in a
        )

    same_as: dict = {}
    for (dataset, method), column in columns.items():  # each against the earlier columns of its own
        own = [m for (d, m), other in same_as.items() if d == dataset and not other]
        same_as[(dataset, method)] = next((m for m in own if same(column, columns[(dataset, m)])), "")
    return [{**row, "same_as": same_as[(row["dataset"], row["method"])]} for row in rows]


def sweep_curves(cells: list[Cell], rows: list[dict]) -> tuple[str, dict] | None:
    """For a grid swept over exactly one key with numeric values: the key and, per (dataset,
    method, frontend), an (n, 3) array of (value, NC, APE) sorted by value, from the finished
    cells; None otherwise. `rows` as table_rows made them from `cells`."""
    keys = {k for c in cells for k, _ in c.sweep}
    if len(keys) != 1:
        return None
    try:
        values = {c: float(c.sweep[0][1]) for c in cells}
    except ValueError:
        return None
    curves: dict = {}
    for cell, row in zip(cells, rows):
        if row["status"] == "ok" and row["ape_mean_rad"] is not None:
            curves.setdefault((cell.dataset, row["method"], cell.frontend), []).append(
                (values[cell], row["nc_mean"], row["ape_mean_rad"])
            )
    return keys.pop(), {k: np.array(sorted(v)) for k, v in curves.items()}


def _best(rows: list[dict], key: str, lower: bool) -> dict:
    """Per (dataset, method) column: the best value of `key` among its measurements (_measured);
    a column without one has none."""
    best = {}
    for r in rows:
        v = r.get(key)
        if not _measured(key, v):
            continue
        col = (r["dataset"], r["method"])
        if col not in best or (v < best[col] if lower else v > best[col]):
            best[col] = v
    return best


def _measured(key: str, value) -> bool:
    """Whether `value` of the figure `key` measured something: a finite number, and an NC above
    0 (NC 0: no correspondence counted, as with nothing tracked or an event tracker's)."""
    return value is not None and math.isfinite(value) and (key != "nc_mean" or value > 0)


#: Table 1's figures: (row key, column title, format, lower is better).
TABLE1_FIGURES = (("nc_mean", "average NC", "{:.0f}", False), ("ape_mean_rad", "average APE [rad]", "{:.3f}", True))


#: The event-rotation literature's figures (evaluation.motion_errors), in table_motion.md.
MOTION_FIGURES = (
    ("omega_rms_deg_s", "omega RMS [deg/s]", "{:.1f}", True),
    ("rpe_1s_mean_deg", "RPE 1 s [deg]", "{:.2f}", True),
)


MOTION_KEYS = (
    "omega_rms_deg_s",
    "omega_rms_x_deg_s",
    "omega_rms_y_deg_s",
    "omega_rms_z_deg_s",
    "rpe_1s_mean_deg",
    "rpe_1s_rmse_deg",
)


def table_markdown(rows: list[dict], figures=TABLE1_FIGURES) -> str:
    """The paper's Table 1: a row per source type (and sweep point), per sequence and method
    (tracker+backend) the average NC and average APE [rad] (or other `figures`); the best of
    each column in bold. A method whose results are an earlier one's (row `same_as`) is no
    column of its own: that one's header names it."""
    sources = list(dict.fromkeys((r["frontend"], r["sweep"]) for r in rows))
    by_key = {(r["dataset"], r["method"], r["frontend"], r["sweep"]): r for r in rows}
    best = [_best(rows, key, lower=lower) for key, _, _, lower in figures]
    name = {r["dataset"]: r.get("dataset_name") or slug(r["dataset"]) for r in rows}
    columns = equal_methods(rows)
    head = ["Source type"]
    for (d, m), equals in columns.items():
        title = markdown_cell(" = ".join([f"{name[d]} {m}", *equals]))
        head += [f"{title}: {label}" for _, label, _, _ in figures]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for frontend, sweep in sources:
        cells = [markdown_cell(frontend + (f" ({sweep})" if sweep else ""))]
        for d, m in columns:
            r = by_key.get((d, m, frontend, sweep))
            if r is None or r["status"] != "ok":
                cells += ["failed" if r else "", markdown_cell((r or {}).get("error", "")[:60])] + [""] * (
                    len(figures) - 2
                )
                continue
            for (key, _, form, _), bests in zip(figures, best):
                value = r.get(key)
                text = form.format(value) if value is not None and value == value else "n/a"
                cells.append(f"**{text}**" if value is not None and value == bests.get((d, m)) else text)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def equal_methods(rows: list[dict]) -> dict[tuple[str, str], list[str]]:
    """Each (dataset, method) of `rows` that is a column of its own, dataset by dataset in table
    order, with the methods whose results are its own (row `same_as`, mark_identical)."""
    datasets = list(dict.fromkeys(r["dataset"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    same_as = {(r["dataset"], r["method"]): r["same_as"] for r in rows}
    return {
        (d, m): [o for o in methods if same_as.get((d, o)) == m]
        for d in datasets
        for m in methods
        if same_as.get((d, m)) == ""
    }


def table_csv(rows: list[dict]) -> str:
    """The rows as CSV, one a cell, with which cells are best per column (best_nc, best_ape)."""
    fields = [
        "dataset",
        "frontend",
        "tracker",
        "backend",
        "method",
        "sweep",
        "status",
        "nc_mean",
        "ape_mean_rad",
        *MOTION_KEYS,
        "orb_keypoints_mean",
        "orb_matches_mean",
        "best_nc",
        "best_ape",
        "same_as",
        "folder",
        "error",
    ]
    best_nc, best_ape = _best(rows, "nc_mean", lower=False), _best(rows, "ape_mean_rad", lower=True)
    buffer = io.StringIO()
    writer = csv.DictWriter(
        buffer, fieldnames=fields, extrasaction="ignore", lineterminator="\n"
    )  # LF, as every file we write
    writer.writeheader()
    for r in rows:
        col = (r["dataset"], r["method"])
        writer.writerow(
            {
                **r,
                "best_nc": int(r["nc_mean"] is not None and r["nc_mean"] == best_nc.get(col)),
                "best_ape": int(r["ape_mean_rad"] is not None and r["ape_mean_rad"] == best_ape.get(col)),
            }
        )
    return buffer.getvalue()


def write_tables(out_root: Path, rows: list[dict]) -> None:
    """table.md (Table 1's layout), table_motion.md, table.csv and table.json in `out_root`."""
    write_text_atomic(out_root / "table.md", table_markdown(rows))
    write_text_atomic(out_root / "table_motion.md", table_markdown(rows, MOTION_FIGURES))
    write_text_atomic(out_root / "table.csv", table_csv(rows))
    write_text_atomic(out_root / "table.json", json_text(rows))
