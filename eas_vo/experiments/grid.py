"""A grid of runs (datasets x frontends x methods x sweep points), each cell run as `eas-vo run`
would in its own folder, in parallel processes (or on a Dask cluster), resumed where a cell's
identity matches."""

from __future__ import annotations

import json
import os
import signal
import sys
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from eas_vo import concurrency
from eas_vo.errors import EasVoError, Interrupted, sigterm_as_interrupt
from eas_vo.experiments.cells import Cell
from eas_vo.experiments.results import OUTPUT_FILES, mark_identical, table_rows, write_figures, write_tables
from eas_vo.io.atomic import remove_stale_temporaries, write_text_atomic
from eas_vo.io.outputs import claim_grid_folder, output_folder


def cell_config(cell: Cell, config_file, assignments: list[str], run_overrides: dict):
    """The resolved configuration of a cell (raises ConfigError for a bad one)."""
    from eas_vo import config

    return config.resolve(
        config_file,
        {
            **run_overrides,
            "dataset": cell.dataset,
            "frontend": cell.frontend,
            "tracker": cell.tracker,
            "backend": cell.backend,
        },
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
    return {
        "status": "failed",
        "error": f"{type(exc).__name__}: {first} (a bug, not a problem with the input: "
        "please report it with the cell's error.txt)",
    }


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
    cells: list[Cell],
    out_root: Path,
    config_file,
    assignments,
    run_overrides,
    jobs: int,
    progress: bool,
    scheduler: str | None = None,
    results: dict | None = None,
):
    """Run the cells not yet complete, `jobs` processes at a time, or on the Dask cluster at
    `scheduler` (its workers must see `out_root`); returns {cell: result} and the count run.
    `results`, if given, is filled in place as cells finish (what an interrupted caller keeps)."""
    from tqdm import tqdm

    from eas_vo.pipeline.identity import run_identity

    results = results if results is not None else {}
    identities = {cell: run_identity(cell_config(cell, config_file, assignments, run_overrides)) for cell in cells}
    done = {cell: completed(out_root, cell, identities[cell]) for cell in cells}
    todo = [cell for cell in cells if done[cell] is None]
    not_run = {"status": "not run", "error": "interrupted before this cell ran"}
    results.update({cell: done[cell] or dict(not_run) for cell in cells})  # one step: never half-filled
    args = (str(out_root), config_file, list(assignments), run_overrides)
    with tqdm(
        total=len(cells), initial=len(cells) - len(todo), disable=not progress, unit="cell", desc="compare"
    ) as bar:
        if scheduler is not None:
            try:
                from distributed import Client
                from distributed import as_completed as dask_completed
            except ImportError:
                raise EasVoError(
                    "--executor dask needs the 'distributed' extra: pip install 'eas-vo[distributed]'"
                ) from None
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
            pool = ProcessPoolExecutor(
                workers, initializer=_worker_start, initargs=(max(1, (os.cpu_count() or 1) // workers),)
            )
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


def open_datasets(cells: list[Cell], config_file, assignments, overrides: dict) -> None:
    """Open each dataset of `cells` once, as they will (simulated, fetched or its events cached
    here, not once per worker process); one that cannot be opened is left to its cells to report."""
    from eas_vo import config as config_mod
    from eas_vo.registry import open_dataset

    for dataset, dataset_sweep in dict.fromkeys(
        (c.dataset, tuple(f"{k}={v}" for k, v in c.sweep if k.startswith("dataset."))) for c in cells
    ):
        try:
            resolved = config_mod.resolve(
                config_file, {**overrides, "dataset": dataset}, list(assignments) + list(dataset_sweep)
            )
            open_dataset(dataset, resolved.dataset).events()
        except EasVoError:
            pass  # its cells will report the error


def run_experiment(
    cells: list[Cell],
    out: Path,
    config_file,
    assignments,
    overrides: dict,
    jobs: int,
    progress: bool,
    scheduler: str | None = None,
) -> tuple[list[dict], int]:
    """What `eas-vo compare` does after parsing: check every cell's configuration (a bad one is
    an error before any work), open each dataset once (simulated, fetched or cached here, not
    once per process), run the cells not yet complete, and write the tables and figures, also
    when interrupted (then Interrupted is raised, saying what was kept). Returns (rows, cells run)."""
    for cell in cells:
        cell_config(cell, config_file, assignments, overrides)
    claim_grid_folder(out)  # new, empty or compare's own: never someone's table.md
    remove_stale_temporaries(out, OUTPUT_FILES)  # of a compare killed while writing them
    open_datasets(cells, config_file, assignments, overrides)
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
