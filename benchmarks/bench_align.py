"""Cost and decisions of `klt`'s `align` fallback (direct photometric alignment where LK's step
has too few inliers): best.toml on the real excerpt (`histeq`, time offset 0.01 s) at its own
frame rate and thinned to every 2nd and 3rd frame (faster motion, where the fallback runs on
a sixth of the frames).

Prints, per frame rate: the fallback frames, the wall time of each (the views' pyramids, the
search, the LK retry and the scores: everything the fallback adds to a frame) as median and
mean [ms], the whole run's frames/s and its APE [rad]. `--save FILE` keeps each fallback's
rotation found (or none); `--compare FILE` prints how far this code's rotations are from a
saved run's (another version's), frame by frame.

    python benchmarks/bench_align.py [--real DIR] [--every 1 2 3] [--save F.npz] [--compare F.npz]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from faster_real import thinned
from study import add_real, real_folder

from eas_vo import config, pipeline
from eas_vo.trackers import alignment, klt


def instrumented_run(folder: Path) -> tuple[dict, list[float], list[np.ndarray | None]]:
    """best.toml on `folder`: (metrics, seconds of each fallback frame, the rotation `align` found there)."""
    seconds: list[float] = []
    found: list[np.ndarray | None] = []
    aligned_step, align = klt.KltTracker._aligned_step, alignment.PhotometricAlignment.align
    pyramid = alignment.PhotometricAlignment.pyramid
    before = [0.0, False]  # the frame's own pyramid, made just before the step; inside the step

    def timed_pyramid(self, image):
        t = time.perf_counter()
        try:
            return pyramid(self, image)
        finally:
            if not before[1]:
                before[0] = time.perf_counter() - t

    def timed_step(self, *args, **kwargs):
        t, before[1] = time.perf_counter(), True
        try:
            return aligned_step(self, *args, **kwargs)
        finally:
            seconds.append(before[0] + time.perf_counter() - t)
            before[:] = [0.0, False]

    def recorded(self, source, image, starts):
        R = align(self, source, image, starts)
        found.append(None if R is None else np.array(R))
        return R

    klt.KltTracker._aligned_step, alignment.PhotometricAlignment.align = timed_step, recorded
    alignment.PhotometricAlignment.pyramid = timed_pyramid
    try:
        cfg = config.resolve("best", {"dataset": str(folder), "frontend": "histeq", "time_offset_s": 0.01}, [])
        t = time.perf_counter()
        result = pipeline.run(cfg)
        wall = time.perf_counter() - t
    finally:
        klt.KltTracker._aligned_step, alignment.PhotometricAlignment.align = aligned_step, align
        alignment.PhotometricAlignment.pyramid = pyramid
    metrics = dict(result.metrics, frames_per_s=result.metrics["frames"] / wall)
    return metrics, seconds, found


def angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(A.T @ B) - 1.0) / 2.0, -1.0, 1.0))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser)
    parser.add_argument("--every", type=int, nargs="+", default=[1, 2, 3], help="keep every N-th frame")
    parser.add_argument("--save", type=Path, help="write each fallback's rotation to this .npz")
    parser.add_argument("--compare", type=Path, help="compare each fallback's rotation with this saved .npz")
    args = parser.parse_args()
    real = real_folder(args.real)
    saved, reference = {}, dict(np.load(args.compare)) if args.compare else None
    print("| frames | fallback frames | per fallback frame, median / mean [ms] | run frames/s | APE [rad] |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for every in args.every:
            metrics, seconds, found = instrumented_run(thinned(real, Path(tmp) / f"every-{every}", every))
            ms = 1e3 * np.array(seconds)
            print(
                f"| every {every} | {len(ms)} | {np.median(ms):.1f} / {ms.mean():.1f} | {metrics['frames_per_s']:.0f} "
                f"| {metrics['ape_mean_rad']:.4f} |",
                flush=True,
            )
            rotations = np.array([np.full((3, 3), np.nan) if R is None else R for R in found]).reshape(-1, 3, 3)
            saved[f"every{every}"], saved[f"every{every}_ape"] = rotations, metrics["ape_mean_rad"]
            if reference is not None:
                theirs = reference[f"every{every}"]
                if len(theirs) != len(rotations):
                    print(f"  every {every}: {len(rotations)} fallbacks here, {len(theirs)} in {args.compare}")
                    continue
                none_differs = int((np.isnan(theirs[:, 0, 0]) != np.isnan(rotations[:, 0, 0])).sum())
                angles = [angle_deg(a, b) for a, b in zip(rotations, theirs) if not np.isnan(a[0, 0] + b[0, 0])]
                print(
                    f"  every {every}: found/none differs on {none_differs}; largest angle between the rotations "
                    f"{max(angles, default=0.0):.4f} deg; APE {metrics['ape_mean_rad'] - float(reference[f'every{every}_ape']):+.2e} rad"
                )
    if args.save:
        np.savez(args.save, **saved)


if __name__ == "__main__":
    main()
