"""The smoothed variant against the paper's chain, on data with ground truth (docs/uncertainty.md).

Each configuration runs once per frontend and sequence with the chain backend (the paper's
rotations chained frame to frame) and once with the pose graph (gtsam), on the same tracker
settings: `paper` is configs/paper.toml with keyframe edges (tracker.klt.keyframe_interval=3,
the pose graph's redundant edges), `best` is configs/best.toml (its keyframes, loops and gyro).
The graph variants are weighted by each edge's covariance (edge_noise = covariance, the default)
and, for comparison, by one isotropic sigma from its inlier count (edge_noise = inliers), each
with the robust kernels given by --kernels. Prints the average APE [rad] (Eq. 3) of each and the
ratio graph / chain, per run and summarised (worst ratio, geometric mean) per data split.

Choice data (where a default is chosen): `synthetic:default` and the real excerpt's first 20 s.
Report data: simulator seeds 51, 52, 53 (not used by any other choice) and the real excerpt's
20-30 s.

    python benchmarks/graph_vs_chain.py [--real DIR | --real ''] [--seeds 51 52 53] [--only LABEL ...]
                                        [--configs paper best] [--kernels none huber cauchy]
                                        [--noise covariance inliers] [--rows FILE]
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np
from select_best import seed_folder
from study import add_real, real_folder

from eas_vo import config, pipeline, registry
from eas_vo.backends.gtsam_graph import GtsamBackend
from eas_vo.evaluation.ape import rotation_errors

SYNTHETIC_FRONTENDS = ("original", "histeq", "slice", "ts", "sits", "eas")
REAL_FRONTENDS = ("histeq", "original")  # the real excerpt has events for its first 0.5 s only
REAL_OFFSET_S = 0.01  # the excerpt's frames lead its ground truth by 10 ms (its README)
CONFIGS = {"paper": ["tracker.klt.keyframe_interval=3"], "best": []}
#: The graph is worse than the chain where its APE exceeds the chain's by more than this.
TOLERANCE = 0.05


def data(real: str, seeds: list[int]) -> dict:
    """{label: (split, dataset, frontends, run overrides)}."""
    found = {"synthetic:default": ("choice", "synthetic:default", SYNTHETIC_FRONTENDS, {})}
    found.update({f"seed {n}": ("report", str(seed_folder(n)), SYNTHETIC_FRONTENDS, {}) for n in seeds})
    if real and Path(real).is_dir():
        for label, split, (start, duration) in (
            ("real 0-20 s", "choice", (0.0, 20.0)),
            ("real 20-30 s", "report", (20.0, 10.0)),
        ):
            extra = {"start_s": start, "duration_s": duration, "time_offset_s": REAL_OFFSET_S}
            found[label] = (split, real, REAL_FRONTENDS, extra)
    elif real:
        print(f"{real}: not found, real data skipped", file=sys.stderr)
    return found


def rows_for(label: str, split: str, dataset: str, frontend: str, extra: dict, name: str, noises, kernels) -> dict:
    """The chain's APE and each graph variant's. Without the gyro in the graph (`paper`) the
    variants solve the chain run's own edges (the tracker does not depend on the backend);
    with it (`best`) each variant is a run of its own, so the gyro's policy decides as in a run."""
    row = {"data": label, "split": split, "config": name, "frontend": frontend}
    sets = CONFIGS[name]
    overrides = {"dataset": dataset, "frontend": frontend, **extra}
    chained = pipeline.run(config.resolve(name, overrides, sets + ["run.backend=chain"]))
    row["chain"] = float(chained.metrics["ape_mean_rad"])
    for noise in noises:
        for kernel in kernels:
            graph = sets + ["run.backend=gtsam", f"backend.edge_noise={noise}", f"backend.robust={kernel}"]
            cfg = config.resolve(name, overrides, graph)
            if cfg.backend.gyro is False:
                R_w_c = GtsamBackend(cfg.backend).solve(len(chained.t), chained.edges, times=chained.t).R_w_c
                errors = rotation_errors(chained.t, R_w_c, dataset_ground_truth(cfg), cfg.run.time_offset_s)
                row[f"{noise}/{kernel}"] = float(np.mean(errors.ape_rad))
            else:
                row[f"{noise}/{kernel}"] = float(pipeline.run(cfg).metrics["ape_mean_rad"])
    return row


def dataset_ground_truth(cfg):
    return registry.open_dataset(cfg.run.dataset, cfg.dataset).ground_truth


def summary(rows: list[dict], variants: list[str]) -> None:
    print("\nsplit, config: per graph variant, runs worse than the chain by > 5 %, worst ratio, geometric-mean ratio")
    for split in ("choice", "report"):
        for name in CONFIGS:
            use = [r for r in rows if r["split"] == split and r["config"] == name]
            if not use:
                continue
            for v in variants:
                ratios = np.array([r[v] / r["chain"] for r in use])
                worse = int(np.sum(ratios > 1 + TOLERANCE))
                gmean = math.exp(np.mean(np.log(ratios)))
                print(
                    f"  {split:6s} {name:5s} {v:20s} {worse}/{len(use)} worse, worst {ratios.max():.3f}, gmean {gmean:.3f}"
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser, "the real recording ('' to leave it out)")
    parser.add_argument("--seeds", type=int, nargs="*", default=[51, 52, 53], help="report simulator seeds")
    parser.add_argument("--only", nargs="*", metavar="LABEL", help="run only these data (e.g. 'seed 51')")
    parser.add_argument("--configs", nargs="*", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--kernels", nargs="*", default=["none", "huber", "cauchy"])
    parser.add_argument("--noise", nargs="*", default=["covariance", "inliers"], choices=["covariance", "inliers"])
    parser.add_argument("--rows", type=Path, help="write every run's APEs to this CSV file")
    args = parser.parse_args()
    real = str(real_folder(args.real)) if args.real else ""
    rows = []
    variants = [f"{noise}/{kernel}" for noise in args.noise for kernel in args.kernels]
    for label, (split, dataset, frontends, extra) in data(real, args.seeds).items():
        if args.only and label not in args.only:
            continue
        for name in args.configs:
            for frontend in frontends:
                row = rows_for(label, split, dataset, frontend, extra, name, args.noise, args.kernels)
                rows.append(row)
                cells = " ".join(f"{v} {row[v]:.4f} ({row[v] / row['chain']:.2f})" for v in variants)
                print(f"{label:18s} {name:5s} {frontend:8s} chain {row['chain']:.4f}  {cells}", flush=True)
                if args.rows:
                    with open(args.rows, "w", newline="") as f:
                        writer = csv.DictWriter(f, list(rows[0]))
                        writer.writeheader()
                        writer.writerows(rows)
    summary(rows, variants)


if __name__ == "__main__":
    main()
