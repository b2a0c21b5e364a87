"""Experiments: every cell of dataset x frontend x tracker x backend x sweep point, run as
`eas-vo run` would, in parallel processes, resumable, summarised as the paper's Table 1
(a row per source type, a column pair per dataset and method = tracker+backend)."""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import signal
import sys
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from eas_vo import concurrency, registry
from eas_vo.config import NO_IMAGES, parse_set
from eas_vo.errors import EasVoError, Interrupted, sigterm_as_interrupt
from eas_vo.io.atomic import json_text, remove_stale_temporaries, write_text_atomic
from eas_vo.io.outputs import claim_grid_folder, output_folder
from eas_vo.io.tables import markdown_cell, slug


@dataclass(frozen=True)
class Method:
    """A column of the table: a tracker, a backend and the settings ((key, value text), ...)
    its cells run with beyond the grid's configuration."""

    tracker: str
    backend: str
    settings: tuple = ()

    @property
    def label(self) -> str:
        """`klt+gtsam`, with its settings: `klt+gtsam (keyframe_interval=3)`."""
        keys = " ".join(f"{k.split('.')[-1]}={v}" for k, v in self.settings)
        return f"{self.tracker}+{self.backend}" + (f" ({keys})" if keys else "")


def grid_methods(trackers: list[str], backends: list[str]) -> list[Method]:
    """Every tracker with every backend, as configured."""
    return [Method(t, b) for t, b in itertools.product(trackers, backends)]


@dataclass(frozen=True)
class Cell:
    """One run of the grid; `folder` is relative to the experiment's output folder."""

    dataset: str
    frontend: str
    tracker: str
    backend: str
    sweep: tuple  # ((key, value text), ...)
    dataset_name: str = ""  # distinct within its grid (plan); default: the dataset's slug
    settings: tuple = ()  # the method's own ((key, value text), ...): Method.settings

    @property
    def method(self) -> Method:
        """The table column the cell belongs to."""
        return Method(self.tracker, self.backend, self.settings)

    @property
    def sweep_label(self) -> str:
        return " ".join(f"{k}={v}" for k, v in self.sweep)

    @property
    def folder(self) -> str:
        parts = [f"{self.frontend}_{self.tracker}_{self.backend}"]
        parts += [f"{k.split('.')[-1]}-{v}" for k, v in self.settings + self.sweep]
        return f"{self.dataset_name or slug(self.dataset)}/{slug('_'.join(parts))}"


def parse_sweeps(sweeps: list[str]) -> list[tuple[str, list[str]]]:
    """`frontend.n=2000,4000` -> [('frontend.n', ['2000', '4000'])], keys validated."""
    out = []
    for sweep in sweeps:
        key, sep, values = sweep.partition("=")
        parse_set(f"{key}=0")  # the key's form
        items = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not items:
            raise EasVoError(f"--sweep {sweep!r}: expected SECTION.KEY=V1,V2,...")
        out.append((key.strip(), items))
    return out


def plan(datasets: list[str], frontends: list[str], methods: list[Method], sweeps: list[str]) -> list[Cell]:
    """The cartesian grid of cells."""
    parsed = parse_sweeps(sweeps)
    points = [tuple(zip([k for k, _ in parsed], combo)) for combo in itertools.product(*[v for _, v in parsed])]
    names = dataset_names(datasets)
    trackers = registry.available("trackers")  # an unknown one is its cells' failure, as any bad setting

    def frontend(f: str, tracker: str) -> str:
        return NO_IMAGES if tracker in trackers and not trackers[tracker].reads_images else f

    cells = [
        Cell(d, frontend(f, m.tracker), m.tracker, m.backend, point, names[d], m.settings)
        for d, f, m, point in itertools.product(datasets, frontends, dict.fromkeys(methods), points or [()])
    ]
    return list(dict.fromkeys(cells))  # a tracker that reads no images runs once, with the `no_image` frontend


def dataset_names(datasets: list[str]) -> dict[str, str]:
    """A distinct file-name-safe name per dataset spec: its last path component, with as many
    parent components as it takes to tell it from the others (`a-hdr_boxes`, `b-hdr_boxes`)."""

    def tail(spec: str, depth: int) -> str:
        parts = Path(spec.rstrip("/")).parts or (spec,)
        return slug("-".join(parts[-depth:]))

    names = {}
    for spec in dict.fromkeys(datasets):
        depth = 1
        while any(tail(other, depth) == tail(spec, depth) for other in datasets if other != spec) and depth < len(Path(spec).parts):
            depth += 1
        names[spec] = tail(spec, depth)
    if len(set(names.values())) < len(names):  # still equal (e.g. `x` and `x/`): tell apart by hash
        names = {spec: f"{name}-{hashlib.sha1(spec.encode()).hexdigest()[:6]}" for spec, name in names.items()}
    return names


def cell_config(cell: Cell, config_file, assignments: list[str], run_overrides: dict):
    """The resolved configuration of a cell (raises ConfigError for a bad one)."""
    from eas_vo import config

    return config.resolve(
        config_file,
        {**run_overrides, "dataset": cell.dataset, "frontend": cell.frontend, "tracker": cell.tracker, "backend": cell.backend},
        list(assignments) + [f"{k}={v}" for k, v in cell.settings + cell.sweep],
    )


def run_cell(cell: Cell, out_root: str, config_file, assignments: list[str], run_overrides: dict) -> dict:
    """Run one cell into its folder (in a worker process). Any error is the cell's failure,
    reported, not raised: a user error's message, or for a bug also its traceback in error.txt."""
    from eas_vo import pipeline

    folder = Path(out_root) / cell.folder
    try:
        cfg = cell_config(cell, config_file, assignments, run_overrides)
        with sigterm_as_interrupt():  # a worker keeps its partial outputs on SIGTERM, however it was started
            metrics = pipeline.run(cfg, folder, replace=True).metrics  # a cell's folder is compare's own
        return {"status": "ok", **metrics}
    except Exception as exc:
        failure = cell_failure(exc)
        details = "" if isinstance(exc, EasVoError) else traceback.format_exc()
        try:
            with output_folder(folder, replace=True) as staging:  # the cell's folder says why, and stays compare's own
                write_text_atomic(staging / "error.txt", failure["error"] + "\n" + details)
        except EasVoError:
            pass  # a folder compare may not replace: the table carries the message
        return failure


def cell_failure(exc: Exception) -> dict:
    """A failed cell's result: a user error's first line; anything else (a bug in eas-vo or a
    plugin) by its type and first line, with a request to report it."""
    first = (str(exc).splitlines() or [""])[0]
    if isinstance(exc, EasVoError):
        return {"status": "failed", "error": first}
    return {"status": "failed", "error": f"{type(exc).__name__}: {first} (a bug, not a problem with the input: "
                                         "please report it with the cell's error.txt)"}


def completed(out_root: Path, cell: Cell, identity: dict) -> dict | None:
    """The metrics of a cell that already finished with the same inputs (pipeline.run_identity:
    version and code, dataset and its content, resolved configuration) and still holds all its
    files, else None: it must run (again)."""
    from eas_vo.pipeline import RUN_FILES

    folder = out_root / cell.folder
    try:
        metrics = json.loads((folder / "metrics.json").read_text())
        same = json.loads((folder / "identity.json").read_text()) == identity
    except (OSError, ValueError):
        return None
    whole = isinstance(metrics, dict) and not metrics.get("partial") and all((folder / f).is_file() for f in RUN_FILES)
    return {"status": "ok", **metrics} if same and whole else None


def run_grid(
    cells: list[Cell], out_root: Path, config_file, assignments, run_overrides, jobs: int, progress: bool,
    scheduler: str | None = None,
    results: dict | None = None,
):
    """Run the cells not yet complete, `jobs` processes at a time, or on the Dask cluster at
    `scheduler` (its workers must see `out_root`); returns {cell: result} and the count run.
    `results`, if given, is filled in place as cells finish (what an interrupted caller keeps)."""
    from tqdm import tqdm

    from eas_vo.pipeline import run_identity

    results = results if results is not None else {}
    identities = {cell: run_identity(cell_config(cell, config_file, assignments, run_overrides)) for cell in cells}
    done = {cell: completed(out_root, cell, identities[cell]) for cell in cells}
    todo = [cell for cell in cells if done[cell] is None]
    not_run = {"status": "not run", "error": "interrupted before this cell ran"}
    results.update({cell: done[cell] or dict(not_run) for cell in cells})  # one step: never half-filled
    args = (str(out_root), config_file, list(assignments), run_overrides)
    with tqdm(total=len(cells), initial=len(cells) - len(todo), disable=not progress, unit="cell", desc="compare") as bar:
        if scheduler is not None:
            try:
                from distributed import Client, as_completed as dask_completed
            except ImportError:
                raise EasVoError("--executor dask needs the 'distributed' extra: pip install 'eas-vo[distributed]'") from None
            with Client(scheduler) as client:
                futures = {client.submit(run_cell, cell, *args, pure=False): cell for cell in todo}
                for future in dask_completed(futures):
                    results[futures[future]] = _result(future)
                    bar.update(1)
        elif jobs <= 1 or len(todo) <= 1:
            for cell in todo:
                results[cell] = run_cell(cell, *args)
                bar.update(1)
        else:
            workers = min(jobs, len(todo))
            pool = ProcessPoolExecutor(workers, initializer=_worker_start, initargs=(max(1, (os.cpu_count() or 1) // workers),))
            futures = {pool.submit(run_cell, cell, *args): cell for cell in todo}
            try:
                for future in as_completed(futures):
                    results[futures[future]] = _result(future)
                    bar.update(1)
            except KeyboardInterrupt:  # Ctrl-C or SIGTERM: stop now, keep every finished cell
                _stop(pool, futures, results)
                for cell in todo:  # a cell whose folder was complete before its worker stopped counts
                    if results[cell]["status"] == "not run":
                        results[cell] = completed(out_root, cell, identities[cell]) or results[cell]
                raise
            pool.shutdown()
    return results, len(todo)


def _result(future) -> dict:
    """A finished cell's result; its failure if its worker could not return one (it died, or
    the result did not reach compare)."""
    try:
        return future.result()
    except Exception as exc:
        return cell_failure(exc)


def _worker_start(threads: int) -> None:
    """A pool worker's start: its share of the cores for eas-vo's own threads (no more threads
    than cores across the workers); on Linux the kernel kills it when the process that started
    it dies (after a `kill -9` of compare its workers ran on through the queue, then waited
    forever). The cell it was running is left as a crashed run's folder, which the next compare
    takes over."""
    concurrency.set_threads(threads)
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _stop(pool: ProcessPoolExecutor, futures: dict, results: dict) -> None:
    """Cancel the queued cells, keep those that finished, and end the running ones with SIGTERM
    (each writes its partial outputs) before returning: no worker outlives compare."""
    for future, cell in futures.items():
        if future.done() and not future.cancelled() and future.exception() is None:
            results[cell] = future.result()
    workers = list(pool._processes.values())  # ProcessPoolExecutor has no public terminate before 3.14
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        process.terminate()
    for process in workers:
        process.join(timeout=30)


def run_experiment(cells: list[Cell], out: Path, config_file, assignments, overrides: dict, jobs: int,
                   progress: bool, scheduler: str | None = None) -> tuple[list[dict], int]:
    """What `eas-vo compare` does after parsing: check every cell's configuration (a bad one is
    an error before any work), open each dataset once (simulated, fetched or cached here, not
    once per process), run the cells not yet complete, and write the tables and figures, also
    when interrupted (then Interrupted is raised, saying what was kept). Returns (rows, cells run)."""
    from eas_vo import config as config_mod
    from eas_vo.registry import open_dataset

    for cell in cells:
        cell_config(cell, config_file, assignments, overrides)
    claim_grid_folder(out)  # new, empty or compare's own: never someone's table.md
    remove_stale_temporaries(out, OUTPUT_FILES)  # of a compare killed while writing them
    for dataset, dataset_sweep in dict.fromkeys(
        (c.dataset, tuple(f"{k}={v}" for k, v in c.sweep if k.startswith("dataset."))) for c in cells
    ):
        try:
            resolved = config_mod.resolve(config_file, {**overrides, "dataset": dataset}, list(assignments) + list(dataset_sweep))
            open_dataset(dataset, resolved.dataset).events()
        except EasVoError:
            pass  # its cells will report the error
    results: dict = {}
    interrupted = None
    try:
        results, n_run = run_grid(cells, out, config_file, assignments, overrides, jobs, progress, scheduler, results)
    except KeyboardInterrupt as exc:  # write the table of what finished; a new invocation resumes
        interrupted, n_run = exc, sum(r["status"] != "not run" for r in results.values())
    rows = mark_identical(out, cells, table_rows(cells, results))
    write_tables(out, rows)
    write_figures(out, cells, rows)
    if interrupted is not None:
        kept = f"the table of the {n_run} finished cells was written to {out}; the same command resumes the rest"
        raise Interrupted.keeping(interrupted, kept) from None
    return rows, n_run


#: The files compare writes in its output folder (write_tables, write_figures).
OUTPUT_FILES = ("table.md", "table.csv", "table.json", "ape_bars.png", "ape_time.png", "ape_sweep.png")


def write_figures(out: Path, cells: list[Cell], rows: list[dict]) -> None:
    """ape_bars.png (APE and NC per source), ape_time.png (APE over time of each finished cell)
    and, for a grid swept over one numeric key, ape_sweep.png; a method whose results are an
    earlier one's (row `same_as`) drawn once, under both names; a frontend in one colour throughout."""
    from eas_vo.evaluation import tum_rotation_errors
    from eas_vo.gallery import PAPER_COLOURS
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


# ----------------------------------------------------------------------------- tables


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
        (t_a, _, q_a), (t_b, _, q_b) = read_tum(a), read_tum(b)
    except (OSError, ValueError):
        return False
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
            (row["nc_mean"], out_root / cell.folder / "trajectory.tum") if row["status"] == "ok" else None)

    def same(a: dict, b: dict) -> bool:
        return a.keys() == b.keys() and all(a[k] is not None and b[k] is not None and a[k][0] == b[k][0]
                                            and same_trajectory(a[k][1], b[k][1]) for k in a)

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
            curves.setdefault((cell.dataset, row["method"], cell.frontend), []).append((values[cell], row["nc_mean"], row["ape_mean_rad"]))
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
MOTION_FIGURES = (("omega_rms_deg_s", "omega RMS [deg/s]", "{:.1f}", True), ("rpe_1s_mean_deg", "RPE 1 s [deg]", "{:.2f}", True))
MOTION_KEYS = ("omega_rms_deg_s", "omega_rms_x_deg_s", "omega_rms_y_deg_s", "omega_rms_z_deg_s", "rpe_1s_mean_deg",
               "rpe_1s_rmse_deg")


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
                cells += ["failed" if r else "", markdown_cell((r or {}).get("error", "")[:60])] + [""] * (len(figures) - 2)
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
    return {(d, m): [o for o in methods if same_as.get((d, o)) == m]
            for d in datasets for m in methods if same_as.get((d, m)) == ""}


def table_csv(rows: list[dict]) -> str:
    fields = ["dataset", "frontend", "tracker", "backend", "method", "sweep", "status", "nc_mean", "ape_mean_rad",
              *MOTION_KEYS, "orb_keypoints_mean", "orb_matches_mean", "best_nc", "best_ape", "same_as", "folder", "error"]
    best_nc, best_ape = _best(rows, "nc_mean", lower=False), _best(rows, "ape_mean_rad", lower=True)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, extrasaction="ignore", lineterminator="\n")  # LF, as every file we write
    writer.writeheader()
    for r in rows:
        col = (r["dataset"], r["method"])
        writer.writerow({**r, "best_nc": int(r["nc_mean"] is not None and r["nc_mean"] == best_nc.get(col)),
                         "best_ape": int(r["ape_mean_rad"] is not None and r["ape_mean_rad"] == best_ape.get(col))})
    return buffer.getvalue()


def write_tables(out_root: Path, rows: list[dict]) -> None:
    write_text_atomic(out_root / "table.md", table_markdown(rows))
    write_text_atomic(out_root / "table_motion.md", table_markdown(rows, MOTION_FIGURES))
    write_text_atomic(out_root / "table.csv", table_csv(rows))
    write_text_atomic(out_root / "table.json", json_text(rows))


