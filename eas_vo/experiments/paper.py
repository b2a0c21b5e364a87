"""What the paper's experiments share: its two sequences and published tables, the methods of
its grids, fetching its data, and the checks a grid passes before any work."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from eas_vo.experiments import grid
from eas_vo.experiments.cells import Cell, Method, plan
from eas_vo.io.atomic import remove_stale_temporaries
from eas_vo.io.outputs import claim_grid_folder

SEQUENCES = ("hdr_boxes", "hdr_poster")


#: The paper's Table 1: (average NC, average APE [rad]) per sequence and source.
PAPER_TABLE1 = {
    "hdr_boxes": {
        "original": (22, 0.69),
        "histeq": (24, 0.39),
        "slice": (344, 0.39),
        "ts": (267, 0.41),
        "sits": (320, 0.35),
        "eas": (62, 0.17),
    },
    "hdr_poster": {
        "original": (33, 0.66),
        "histeq": (58, 0.58),
        "slice": (293, 0.32),
        "ts": (238, 0.30),
        "sits": (272, 0.32),
        "eas": (93, 0.25),
    },
}


#: The paper's Table 2 (monocular ORB-SLAM2): keyframe APE [m], ORB features and matches per image.
PAPER_TABLE2 = {
    "hdr_boxes": {
        "original": {"ape_m": 0.021, "features": 199, "matches": 94},
        "eas": {"ape_m": 0.029, "features": 344, "matches": 57},
    },
    "hdr_poster": {
        "original": {"ape_m": 0.049, "features": 212, "matches": 114},
        "eas": {"ape_m": 0.058, "features": 392, "matches": 53},
    },
}


#: What the paper ran: its first 25 s of each sequence (§4.2), its configuration, time offset estimated.
PAPER_DURATION_S = 25.0


#: Table 2's window: §4.3 names none and Fig. 4 shows keyframes "in the whole trajectories of
#: the camera", so the whole sequences (None).
PAPER_TABLE2_DURATION_S = None


#: The --dataset spec of each sequence (fetched on first use).
SPECS = {name: f"ecd:{name}" for name in SEQUENCES}


def fetch_sequences(progress: bool, specs=None) -> None:
    """Fetch the sequences `specs` (default: the paper's two) unless present and verified."""
    from eas_vo.registry import fetchable

    for spec in SPECS.values() if specs is None else specs:
        plugin, name = fetchable(spec)
        plugin.fetch(name, progress=progress)


#: The paper's method: klt's consecutive edges chained.
PAPER = Method("klt", "chain")


#: The smoothed method beside it in the default grids (reproduce table1, compare without
#: --trackers/--backends): klt also measures keyframe edges (a keyframe every 3rd frame, as
#: configs/best.toml has it) and the gtsam pose graph fits all edges. On consecutive edges
#: alone a pose graph has nothing to smooth: its trajectory is the chain's.
SMOOTHED = Method("klt", "gtsam", (("tracker.klt.keyframe_interval", "3"),))


def default_methods(tracker: str, backend: str) -> list[Method]:
    """compare's methods when neither trackers nor backends are given: the configuration's,
    and beside the paper's klt+chain the smoothed one (SMOOTHED)."""
    method = Method(tracker, backend)
    return [method, SMOOTHED] if method == PAPER else [method]


def table1_methods(backends) -> list[Method]:
    """Table 1's columns: the paper's klt+chain, and klt with each other backend (a pose graph)
    fed klt's keyframe edges as SMOOTHED is: on the paper's consecutive edges alone it would
    only repeat the chain's trajectory."""
    return [PAPER if b == PAPER.backend else Method("klt", b, SMOOTHED.settings) for b in backends]


def paper_cells(frontends, methods) -> list[Cell]:
    """The grid, each sequence's cells in a folder named after it."""
    cells = plan(list(SPECS.values()), list(frontends), list(methods), [])
    names = {spec: name for name, spec in SPECS.items()}
    return [dataclasses.replace(c, dataset_name=names[c.dataset]) for c in cells]


def run_overrides(duration_s: float | None, orb: bool) -> dict:
    """The [run] values of the paper's runs: its window, the time offset estimated, ORB statistics for Table 2."""
    return {
        "start_s": 0.0,
        "duration_s": duration_s,
        "time_offset_s": None,
        "time_offset_auto": True,
        "orb_stats": orb or None,
    }


#: The files reproduce writes in its output folder beside compare's.
OUTPUT_FILES = ("table1.md", "table1.json", "table2.md", "table2.json", "fig3_*.png", "fig4_*.png")


def check_cells(cells, config: str, overrides: dict, out: Path) -> None:
    """Every cell's configuration resolved (a bad --config, key or backend is an error) and
    `out` claimed (new, empty or a grid folder: io.claim_grid_folder) before any download; then
    the temporary files of a reproduce killed while writing into `out` removed."""
    for cell in cells:
        grid.cell_config(cell, config, [], overrides)
    claim_grid_folder(out)
    remove_stale_temporaries(out, OUTPUT_FILES)


#: Table 2's sources in the paper.
TABLE2_SOURCES = ("original", "eas")
