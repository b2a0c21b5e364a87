"""What the IMU's clock is worth, and whether the run notices it, on real images: the real
excerpt given a 1 kHz gyro made from its ground truth (white noise 0.003 rad/s/sqrt(Hz), a
constant bias; stamped on the ground truth's clock, about 9 ms behind the frames), run with
best.toml and the gyro read at several `run.imu_time_offset_s`, then from 0 with
`run.imu_time_offset_auto`. Prints average APE [rad] per window and the run's IMU warning, if
any (for auto: the offsets the backend used).

    python benchmarks/gyro_clock.py [--real DIR] [--offsets 0 0.008 0.009 0.01 0.011] [--seed 0]
                                    [--bias 0.01] [--set SECTION.KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp
from study import add_real, real_folder

from eas_vo import config, pipeline

WINDOWS = {"20-30 s": (20.0, 10.0), "25-30 s": (25.0, 5.0), "0-30 s": (0.0, 30.0)}


def with_gyro_from_ground_truth(real: Path, out: Path, seed: int, bias_rad_s: float = 0.01) -> Path:
    """`out`: the excerpt's files linked, and an imu.txt integrating to its ground truth, with a
    constant bias drawn with standard deviation `bias_rad_s` per axis [rad/s]."""
    out.mkdir(parents=True, exist_ok=True)
    for name in ("calib.txt", "events.txt", "groundtruth.txt", "images.txt", "images"):
        (out / name).symlink_to(real.resolve() / name)
    gt = np.loadtxt(real / "groundtruth.txt")
    t = np.arange(gt[0, 0], gt[-1, 0], 0.001)
    R = Slerp(gt[:, 0], Rotation.from_quat(gt[:, 4:8]))(t)
    rng = np.random.default_rng(seed)
    rate = (R[:-1].inv() * R[1:]).as_rotvec() / 0.001  # the mean rate over each millisecond, at its middle
    gyro = rate + rng.normal(0, bias_rad_s, 3) + rng.normal(0, 0.003 * np.sqrt(1000), rate.shape)
    np.savetxt(out / "imu.txt", np.column_stack([t[:-1] + 0.0005, np.zeros_like(gyro), gyro]), fmt="%.9f")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_real(parser)
    parser.add_argument("--offsets", type=float, nargs="+", default=[0.0, 0.008, 0.009, 0.01, 0.011])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--bias", type=float, default=0.01, help="standard deviation of the gyro's bias per axis [rad/s]"
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="change best.toml (repeatable)"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rig = with_gyro_from_ground_truth(real_folder(args.real), Path(tmp) / "rig", args.seed, args.bias)
        print("| run.imu_time_offset_s | " + " | ".join(WINDOWS) + " | warning |")
        print("|---" * (len(WINDOWS) + 2) + "|")
        rows = [(f"{offset:g}", [f"run.imu_time_offset_s={offset}"]) for offset in args.offsets]
        for label, changes in rows + [("auto (from 0)", ["run.imu_time_offset_auto=true"])]:
            cells, said = [], []
            for start, duration in WINDOWS.values():
                cfg = config.resolve(
                    "best",
                    {
                        "dataset": str(rig),
                        "frontend": "histeq",
                        "start_s": start,
                        "duration_s": duration,
                        "time_offset_s": 0.01,
                    },
                    changes + args.set,
                )
                metrics = pipeline.run(cfg).metrics
                cells.append(f"{metrics['ape_mean_rad']:.4f}")
                said += [
                    "looks like " + line.split("run.imu_time_offset_s = ")[-1].split(" would")[0]
                    for line in metrics["data_warnings"]
                ]
                if metrics["imu_time_offset_estimated"]:
                    said.append(f"read at {metrics['imu_time_offset_s']:.4f}")
            print(f"| {label} | " + " | ".join(cells) + f" | {'; '.join(said) or '-'} |", flush=True)


if __name__ == "__main__":
    main()
