"""Peak memory of a run over a 100-million-event sequence (event-only, the default sequence's
events tiled in time), first with the text parse into the cache, then from the cache.

    python benchmarks/bench_memory.py [--events 100000000] [--frontend ts]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time

import numpy as np
from bench_events import BENCH_ABOUT


def make_folder(n_events: int):
    from eas_vo.eventfile import format_events
    from eas_vo.io.atomic import atomic_path, write_text_atomic
    from eas_vo.io.cache import cache_folder
    from eas_vo.registry import open_dataset

    folder = cache_folder("bench", BENCH_ABOUT) / f"events_only_{n_events}"
    if (folder / "events.txt").exists():
        return folder
    base = open_dataset("synthetic:default")
    events = np.asarray(base.events())
    span = float(events["t"][-1] - events["t"][0]) + 1e-3
    folder.mkdir(parents=True, exist_ok=True)
    write_text_atomic(folder / "calib.txt", " ".join(f"{v:.12g}" for v in base.camera.calib_values()) + "\n")
    with atomic_path(folder / "events.txt") as tmp, open(tmp, "wb") as fh:
        written, copy = 0, 0
        while written < n_events:
            chunk = events[: n_events - written].copy()
            chunk["t"] += copy * span
            for start in range(0, len(chunk), 1_000_000):
                fh.write(format_events(chunk[start : start + 1_000_000]))
            written += len(chunk)
            copy += 1
    return folder


def run(folder, frontend: str) -> tuple[float, float]:
    """(wall seconds, peak RSS of the run process [MiB])."""
    t0 = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "eas_vo",
            "run",
            "--dataset",
            str(folder),
            "--frontend",
            frontend,
            "--set",
            "dataset.sample_rate_hz=20",
            "--quiet",
            "--out",
            str(folder / f"run_{frontend}"),
            "--overwrite",
        ],
        check=True,
        stdout=subprocess.DEVNULL,
        cwd=folder,  # not the repository root: see tests/conftest.py
    )
    elapsed = time.perf_counter() - t0
    return elapsed, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--events", type=int, default=100_000_000)
    parser.add_argument("--frontend", default="ts", help="ts consumes every event; slice only N per sample")
    args = parser.parse_args()
    folder = make_folder(args.events)
    size_gb = (folder / "events.txt").stat().st_size / 1e9
    print(f"{args.events:,} events ({size_gb:.1f} GB of text), event-only, sampled at 20 Hz, frontend {args.frontend}")
    for label in ("first run (parse + cache)", "second run (cached)"):
        elapsed, peak = run(folder, args.frontend)
        print(
            f"  {label:28s} {elapsed:6.1f} s, peak RSS so far {peak:7.0f} MiB ({peak * 2**20 / args.events:.1f} B/event)"
        )
    print("  (peak RSS counts the mapped cache pages the run touched; the limit asked is 4 GiB)")


if __name__ == "__main__":
    main()
