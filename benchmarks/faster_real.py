"""Faster real motion than the excerpt's: its frames thinned to every 2nd or 3rd (the same
images and motion blur, two or three times the rotation between frames: about 43 and 65
degrees at its last 5 s's p95 speed), run with best.toml and each tracker (`match` with its own
defaults and best.toml's loop closure), without an IMU and with a
1 kHz gyro made from the ground truth (benchmarks/gyro_clock.py, read at the 9 ms its clock
asks for). Prints average APE [rad] per window (`histeq`, time offset 0.01 s).

    python benchmarks/faster_real.py [--real DIR] [--every 1 2 3] [--trackers klt hybrid match]
                                     [--set SECTION.KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from gyro_clock import with_gyro_from_ground_truth
from study import add_real, add_smoke, first, real_folder, window

from eas_vo import config, pipeline

WINDOWS = {"0-20 s": (0.0, 20.0), "20-30 s": (20.0, 10.0), "0-30 s": (0.0, 30.0)}
TRACKERS = {
    "klt": ("klt", []),
    "hybrid": ("klt", ["tracker.fallback=match"]),
    "match": ("match", ["tracker.loop_closure=true", "tracker.loop_geometry=homography"]),
}
GYRO_CLOCK_S = 0.009  # where the made gyro's clock sits against the frames (gyro_clock.py)


def thinned(folder: Path, out: Path, every: int) -> Path:
    """`out`: `folder`'s files linked, with only every `every`-th frame listed in images.txt."""
    out.mkdir(parents=True)
    for entry in folder.iterdir():
        if entry.name != "images.txt":
            (out / entry.name).symlink_to(entry.resolve())
    lines = (folder / "images.txt").read_text().splitlines(keepends=True)
    (out / "images.txt").write_text("".join(lines[::every]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser)
    parser.add_argument("--every", type=int, nargs="+", default=[1, 2, 3], help="keep every N-th frame")
    parser.add_argument("--trackers", nargs="+", default=list(TRACKERS), choices=list(TRACKERS))
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="change best.toml for every tracker's runs (repeatable; a key a tracker lacks is an error)",
    )
    add_smoke(parser)
    args = parser.parse_args()
    real = real_folder(args.real)
    windows = {label: window(*span, args.smoke) for label, span in first(WINDOWS.items(), args.smoke)}
    with tempfile.TemporaryDirectory() as tmp:
        rig = with_gyro_from_ground_truth(real, Path(tmp) / "rig", seed=0)
        print("| frames | IMU | tracker | " + " | ".join(windows) + " |")
        print("|---" * (len(windows) + 3) + "|")
        for every in first(args.every, args.smoke):
            for imu, source in (("-", real), ("gyro", rig)):
                folder = thinned(source, Path(tmp) / f"every-{every}-{imu}", every)
                for name in first(args.trackers, args.smoke):
                    tracker, changes = TRACKERS[name]
                    clock = [f"run.imu_time_offset_s={GYRO_CLOCK_S}"] if source is rig else []
                    cells = []
                    for start, duration in windows.values():
                        cfg = config.resolve(
                            "best",
                            {
                                "dataset": str(folder),
                                "frontend": "histeq",
                                "tracker": tracker,
                                "start_s": start,
                                "duration_s": duration,
                                "time_offset_s": 0.01,
                            },
                            changes + clock + args.set,
                        )
                        cells.append(f"{pipeline.run(cfg).metrics['ape_mean_rad']:.3f}")
                    print(f"| every {every} | {imu} | {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
