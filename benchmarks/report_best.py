"""configs/best.toml reported on data that did not choose it (docs/best_config.md), beside
`paper.toml` and v0.1's `best.toml`: average APE [rad] on the real excerpt's last 10 and 5 s
and whole 30 s (`histeq`, time offset 0.01 s) and on simulator seeds (`eas`) that
benchmarks/select_best.py never sees; then frames/s and real-time factor of `best.toml`
(best of 3 runs).

    python benchmarks/report_best.py [--real DIR | --real ''] [--seeds 41 42 43] [--fast-seeds 74 75 76]
                                     [--sequence DIR ...] [--no-speed] [--set SECTION.KEY=VALUE ...]

Seeds are simulated once into $EAS_VO_CACHE_DIR/simulated/seed-N (about 40 s each; at speed 4,
seed-N-speed-4, about 5 minutes each).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from select_best import DEVELOPMENT_FAST_SEEDS, SELECTION_SEEDS, seed_folder
from study import SMOKE_S, add_real, add_smoke, first, real_folder, simulated_for, window

from eas_vo import config, pipeline

#: v0.1's configs/best.toml (f472285), as `--set` assignments on top of today's defaults. Checked
#: against that commit's own code on the 22 report seeds: within 13 % of it on each (README).
V01_BEST = [
    "tracker.geometry=rotation",
    "tracker.max_corners=1000",
    "tracker.lk_max_level=5",
    "tracker.threshold2=300",
    "tracker.keyframe_interval=3",
    "backend.robust=huber",
    "backend.edge_noise=inliers",  # its edges' one sigma from their inlier count
]
CONFIGS = {"paper.toml": ("paper", []), "v0.1's best.toml": (None, V01_BEST), "best.toml": ("best", [])}
REAL_WINDOWS = {"real 20-30 s": (20.0, 10.0), "real 25-30 s": (25.0, 5.0), "real 0-30 s": (0.0, 30.0)}


def run(name: str, dataset: str, frontend: str, extra: dict, best_sets: list[str]) -> dict:
    file, assignments = CONFIGS[name]
    backend = {} if file else {"backend": "gtsam"}
    assignments = assignments + (best_sets if name == "best.toml" else [])
    cfg = config.resolve(file, {"dataset": dataset, "frontend": frontend, **backend, **extra}, assignments)
    return pipeline.run(cfg).metrics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser, "the real recording ('' to leave it out)")
    parser.add_argument("--seeds", type=int, nargs="*", default=[41, 42, 43], help="simulator seeds not used to choose")
    parser.add_argument(
        "--fast-seeds",
        type=int,
        nargs="*",
        default=[],
        metavar="N",
        help="also seeds simulated at --fast-speed (e.g. 74 75 76; not 71-73, which the gyro model was corrected on)",
    )
    parser.add_argument("--fast-speed", type=float, default=4.0, help="the speed of --fast-seeds (default 4)")
    parser.add_argument(
        "--sequence",
        action="append",
        default=[],
        metavar="DIR",
        help="also report on this sequence with eas (repeatable; e.g. eas-vo simulate --illumination 0.1)",
    )
    parser.add_argument("--no-speed", action="store_true", help="skip the speed measurement")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="report best.toml with this value changed (repeatable)",
    )
    add_smoke(parser)
    args = parser.parse_args()
    real = str(real_folder(args.real)) if args.real else ""
    smoke = args.smoke
    cut = {"duration_s": SMOKE_S} if smoke else {}
    if set(args.seeds) & set(SELECTION_SEEDS):
        raise SystemExit(
            f"seeds {sorted(set(args.seeds) & set(SELECTION_SEEDS))} took part in a selection (select_best.py): report on others"
        )
    if args.fast_speed == 4.0 and set(args.fast_seeds) & set(DEVELOPMENT_FAST_SEEDS):
        raise SystemExit(
            f"seeds {sorted(set(args.fast_seeds) & set(DEVELOPMENT_FAST_SEEDS))} at speed 4 were developed on: report on others"
        )
    columns = {}
    if real and Path(real).is_dir():
        columns.update(
            {
                label: (
                    real,
                    "histeq",
                    {**dict(zip(("start_s", "duration_s"), window(s, d, smoke))), "time_offset_s": 0.01},
                )
                for label, (s, d) in first(REAL_WINDOWS.items(), smoke)
            }
        )
    elif real:
        print(f"{real}: not found, real columns skipped", file=sys.stderr)
    columns.update({f"seed {n}": (str(seed_folder(n, smoke=smoke)), "eas", {}) for n in first(args.seeds, smoke)})
    columns.update(
        {
            f"seed {n} (speed {args.fast_speed:g})": (str(seed_folder(n, args.fast_speed, smoke)), "eas", {})
            for n in first(args.fast_seeds, smoke)
        }
    )
    names = [Path(d).name for d in args.sequence]
    columns.update({(name if names.count(name) == 1 else d): (d, "eas", cut) for name, d in zip(names, args.sequence)})
    print("| | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for name in CONFIGS:
        cells = [f"{run(name, *column, args.set)['ape_mean_rad']:.4f}" for column in columns.values()]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    if args.no_speed:
        return
    # {label: (column, --set assignments)}
    speed = {"synthetic:default": (("synthetic:default", "eas", {}), args.set + simulated_for(smoke))}
    if "real 0-30 s" in columns:
        speed["real 0-30 s"] = (columns["real 0-30 s"], args.set)
    for label, (column, sets) in speed.items():
        runs = 1 if smoke else 3
        m = max((run("best.toml", *column, sets) for _ in range(runs)), key=lambda m: m["realtime_factor"])
        print(
            f"best.toml on {label} (best of 3): {m['frames_per_s']:.0f} frames/s, {m['realtime_factor']:.1f}x real time"
        )


if __name__ == "__main__":
    main()
