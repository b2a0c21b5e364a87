"""How `eas-vo compare` scales with its worker processes: the paper's grid (the six sources with
the paper's configuration, klt + chain) on one dataset, run from scratch with `--jobs 1` and
with `--jobs N` (default: every core), alternated, best of --repeat; prints each one's wall
time, cells/s and their ratio.

    python benchmarks/bench_compare.py [--dataset synthetic:default] [--jobs 2] [--repeat 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from eas_vo import registry

SOURCES = "original,histeq,slice,ts,sits,eas"


def grid_seconds(dataset: str, jobs: int, folder: Path) -> tuple[float, int]:
    """Wall time [s] of one `eas-vo compare` of the six sources with --config paper into a new
    folder, and how many cells it ran."""
    argv = [
        sys.executable,
        "-m",
        "eas_vo",
        "compare",
        "--dataset",
        dataset,
        "--frontends",
        SOURCES,
        "--config",
        "paper",
        "--jobs",
        str(jobs),
        "--quiet",
        "--out",
        str(folder),
    ]
    t = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    if done.returncode != 0:
        raise SystemExit(f"compare --jobs {jobs} failed: {done.stderr.strip()}")
    return seconds, len(json.loads((folder / "table.json").read_text()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default="synthetic:default")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    registry.open_dataset(args.dataset).events()  # simulated and cached outside the timing
    seconds: dict[int, list[float]] = {1: [], args.jobs: []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeat):
            for jobs in seconds:
                took, cells = grid_seconds(args.dataset, jobs, Path(tmp) / f"jobs{jobs}-{r}")
                seconds[jobs].append(took)
    print(
        f"compare, the six sources with paper.toml on {args.dataset}: {cells} cells (best of {args.repeat}, alternated):"
    )
    for jobs, times in seconds.items():
        print(f"  --jobs {jobs}: {min(times):6.1f} s  ({cells / min(times):.2f} cells/s)")
    if args.jobs > 1:
        print(f"  --jobs {args.jobs} / --jobs 1: {min(seconds[1]) / min(seconds[args.jobs]):.2f}x faster")


if __name__ == "__main__":
    main()
