"""The event-rotation benchmark (`eas-vo reproduce rotation`): the Event Camera Dataset's four
rotation sequences scored under CMax-SLAM's protocol (evaluation.rotation_protocol), our
methods beside the published ones (Guo and Gallego, IEEE T-RO 2024, Table III)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from eas_vo.experiments import grid
from eas_vo.experiments.cells import Cell, Method
from eas_vo.experiments.results import mark_identical, table_rows, write_tables
from eas_vo.io.atomic import atomic_path, json_text, remove_stale_temporaries, write_text_atomic
from eas_vo.io.outputs import claim_grid_folder

SEQUENCES = ("shapes_rotation", "poster_rotation", "boxes_rotation", "dynamic_rotation")

#: The --dataset spec of each sequence (fetched on first use).
SPECS = {name: f"ecd:{name}" for name in SEQUENCES}

#: The published rows of CMax-SLAM's Table III on these sequences: {method: {sequence:
#: (absolute RMS [deg], relative RMS [deg/s]) or None where the method failed}}.
PUBLISHED = {
    method: dict(zip(SEQUENCES, rows))
    for method, rows in {  # in the order of SEQUENCES
        "CMax-omega front end": ((7.164, 6.536), (7.263, 5.985), (9.241, 6.846), (5.535, 3.696)),
        "CMax-SLAM (linear spline)": ((4.953, 6.712), (5.653, 6.357), (5.418, 6.751), (3.380, 3.586)),
        "CMax-SLAM (cubic spline)": ((4.974, 6.821), (5.674, 6.497), (5.391, 6.761), (3.374, 3.618)),
        "RTPT": ((3.224, 3.167), (8.135, 9.423), (2.973, 2.375), (1.873, 1.991)),
        "CMax-GAE": ((3.961, 2.777), (4.010, 3.612), None, (4.840, 1.755)),
        "IMU dead reckoning": ((46.803, 6.470), (45.743, 5.746), (46.979, 6.911), (44.531, 4.183)),
    }.items()
}

CITATION = (
    'S. Guo and G. Gallego, "CMax-SLAM: Event-based Rotational-Motion Bundle Adjustment and SLAM System using '
    'Contrast Maximization", IEEE Transactions on Robotics, 2024 (arXiv 2403.08119), Table III'
)


@dataclass(frozen=True)
class RotationMethod:
    """A row of ours: its name, the configuration it runs with, and its cells' source and method."""

    label: str
    config: str
    frontend: str
    method: Method


#: Our rows. The frame methods run on EAS images (the paper's source); `blind` measures nothing,
#: so its graph holds the gyro alone.
METHODS = (
    RotationMethod("paper.toml (EAS, klt + chain)", "paper", "eas", Method("klt", "chain")),
    RotationMethod("best.toml without gyro", "best", "eas", Method("klt", "gtsam", (("backend.gtsam.gyro", "false"),))),
    RotationMethod("best.toml with gyro", "best", "eas", Method("klt", "gtsam", (("backend.gtsam.gyro", "true"),))),
    RotationMethod("cmax + chain (events only)", "paper", "eas", Method("cmax", "chain")),
    RotationMethod(
        "cmax + gtsam with gyro", "paper", "eas", Method("cmax", "gtsam", (("backend.gtsam.gyro", "true"),))
    ),
    RotationMethod(
        "gyro alone (gtsam, dead reckoning)",
        "paper",
        "eas",
        Method("blind", "gtsam", (("backend.gtsam.gyro", "true"),)),
    ),
)

#: The files reproduce rotation writes in its output folder beside compare's tables.
OUTPUT_FILES = ("rotation.md", "rotation.json", "rotation_*.png")


def run_overrides(duration_s: float) -> dict:
    """The [run] values of every cell: the sequence's first `duration_s` seconds, the timestamps
    as recorded (the protocol estimates no time offset)."""
    return {"start_s": 0.0, "duration_s": duration_s, "time_offset_s": 0.0, "time_offset_auto": False}


def plan_cells(methods=METHODS) -> list[tuple[RotationMethod, Cell]]:
    """(method, cell) for each sequence and method, each sequence's cells in a folder named after it."""
    from eas_vo.experiments.cells import plan

    pairs = []
    for name, spec in SPECS.items():
        for m in methods:
            (cell,) = plan([spec], [m.frontend], [m.method], [])
            pairs.append((m, dataclasses.replace(cell, dataset_name=name)))
    return pairs


def rotation_benchmark(out: Path, duration_s: float, jobs: int = 1, progress: bool = False):
    """Fetch the four sequences, run every method on each one's first `duration_s` seconds
    (cells already complete are kept), score them under the protocol, and write rotation.md,
    rotation.json, a figure per sequence and compare's tables. Returns (rows, cells run, markdown)."""
    from eas_vo.experiments.paper import fetch_sequences

    pairs = plan_cells()
    overrides = run_overrides(duration_s)
    for m, cell in pairs:
        grid.cell_config(cell, m.config, [], overrides)  # a bad configuration fails before any download
    claim_grid_folder(out)
    remove_stale_temporaries(out, OUTPUT_FILES)
    fetch_sequences(progress, SPECS.values())
    results: dict = {}
    n_run = 0
    for config in dict.fromkeys(m.config for m, _ in pairs):
        cells = [c for m, c in pairs if m.config == config]
        grid.open_datasets(cells, config, [], overrides)
        done, ran = grid.run_grid(cells, out, config, [], overrides, jobs, progress)
        results.update(done)
        n_run += ran
    cells = [c for _, c in pairs]
    rows = mark_identical(out, cells, table_rows(cells, results))
    write_tables(out, rows)
    scores = _score_cells(out, pairs, rows, duration_s)
    for row, (m, cell), score in zip(rows, pairs, scores):
        row["label"], row["config"] = m.label, m.config
        row["realtime_factor"] = results.get(cell, {}).get("realtime_factor")
        row.update(score.summary() if score is not None else {})
    markdown = rotation_markdown(rows, duration_s)
    write_text_atomic(out / "rotation.md", markdown)
    write_text_atomic(
        out / "rotation.json",
        json_text(
            {
                "protocol": PROTOCOL_TEXT.format(duration=f"{duration_s:g} s"),
                "published": PUBLISHED,
                "ours": rows,
                "duration_s": duration_s,
            }
        ),
    )
    _figures(out, pairs, scores)
    return rows, n_run, markdown


def _score_cells(out: Path, pairs, rows: list[dict], duration_s: float) -> list:
    """Each finished cell's ProtocolScore; None for a failed cell, and for one the protocol
    cannot score, which becomes a failed cell saying why."""
    from eas_vo.errors import EasVoError
    from eas_vo.experiments.external import protocol_score
    from eas_vo.registry import open_dataset

    datasets: dict = {}
    scores = []
    for (_, cell), row in zip(pairs, rows):
        scores.append(None)
        if row["status"] != "ok":
            continue
        try:
            if cell.dataset not in datasets:
                datasets[cell.dataset] = open_dataset(cell.dataset)
            scores[-1] = protocol_score(datasets[cell.dataset], out / cell.folder / "trajectory.tum", duration_s)
        except EasVoError as exc:
            row["status"], row["error"] = "failed", f"the protocol cannot score it: {exc}"
    return scores


def _figures(out: Path, pairs, scores: list) -> None:
    """rotation_SEQUENCE.png: each method's absolute and 1 s relative error over time."""
    from eas_vo.plots import plot_protocol_errors

    for name in SEQUENCES:
        series = {m.label: s for (m, cell), s in zip(pairs, scores) if cell.dataset_name == name and s is not None}
        if series:
            with atomic_path(out / f"rotation_{name}.png") as tmp:
                plot_protocol_errors(tmp, series, title=f"{name}: error against the smoothed ground truth")


PROTOCOL_TEXT = (
    "the first {duration} of each sequence; the motion-capture ground truth low-pass filtered by a Gaussian "
    "on the rotation manifold over a 50 ms window (sigma 10 ms); the estimate aligned to it by the one pose at "
    "t0 = 1.0 s; absolute error: the RMS of the rotation angle at the estimate's own poses [deg]; relative "
    "error: the RMS over 1 s spans starting every 0.1 s of the angle between the two relative rotations "
    "[deg/s]; timestamps as recorded (no time offset estimated)"
)


def rotation_markdown(rows: list[dict], duration_s: float) -> str:
    """Ours beside the published rows: absolute and relative error per sequence, then our
    real-time factor on this machine."""
    duration = "30 s" if duration_s == 30 else f"{duration_s:g} s (the published rows score 30 s)"
    lines = [
        "# Rotation on the Event Camera Dataset's rotation sequences, CMax-SLAM's protocol",
        "",
        "Protocol: " + PROTOCOL_TEXT.format(duration=duration) + ".",
        "",
        f"Published rows: {CITATION}; none of them ran in real time there. Ours: this machine, "
        "`eas-vo reproduce rotation`.",
        "",
    ]
    labels = list(dict.fromkeys(r["label"] for r in rows))
    by_key = {(r["label"], r["dataset_name"]): r for r in rows}
    for title, key, published_index, digits in (
        ("Absolute error, RMS [deg]", "absolute_rms_deg", 0, 3),
        ("Relative error over 1 s, RMS [deg/s]", "relative_rms_deg_s", 1, 3),
    ):
        lines += [f"## {title}", "", "| method | " + " | ".join(SEQUENCES) + " |", "|---" * (len(SEQUENCES) + 1) + "|"]
        for label in labels:
            cells = []
            for seq in SEQUENCES:
                r = by_key.get((label, seq), {})
                value = r.get(key)
                cells.append(f"{value:.{digits}f}" if value is not None else r.get("status", "-"))
            lines.append(f"| ours: {label} | " + " | ".join(cells) + " |")
        for method, per_seq in PUBLISHED.items():
            cells = [f"{v[published_index]:.3f}" if v is not None else "fails" for v in per_seq.values()]
            lines.append(f"| published: {method} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Real-time factor of ours on this machine", "", "| method | " + " | ".join(SEQUENCES) + " |"]
    lines.append("|---" * (len(SEQUENCES) + 1) + "|")
    for label in labels:
        cells = [
            f"{by_key[(label, s)]['realtime_factor']:.2f}x"
            if by_key.get((label, s), {}).get("realtime_factor") is not None
            else "-"
            for s in SEQUENCES
        ]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        lines += ["Failed cells:", ""] + [f"- {r['label']} on {r['dataset_name']}: {r['error']}" for r in failed] + [""]
    return "\n".join(lines)
