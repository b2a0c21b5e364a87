"""ORB-SLAM3's speed on a frontend's images beside eas-vo's own trackers on the same images,
in one run: monocular ORB-SLAM3 (the slam extra, in its child process: the figure includes
sending each image there) and eas-vo with configs/paper.toml and configs/best.toml (tracker
and backend, the frontend's images computed once beforehand, as for ORB-SLAM3).

Prints frames/s of each and the real-time factor (sequence duration / processing time).

    python benchmarks/bench_slam.py [--dataset synthetic:walk] [--frontend original] [--vocabulary FILE]
        [--set SECTION.KEY=VALUE ...] [--repeat 3]

Without --vocabulary, one is trained on the sequence's images first (eas-vo vocabulary's
defaults, k=10, L=4; not timed).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from eas_vo import config, pipeline


def frontend_images(cfg) -> tuple[list[np.ndarray], np.ndarray]:
    rc = cfg.run
    parts = pipeline.open_pipeline(cfg)
    samples = list(parts.dataset.samples(rc.start_s, rc.duration_s))
    return [parts.frontend(s) for s in samples], np.array([s.t for s in samples])


def eas_vo_seconds(cfg, images, times) -> float:
    """Tracker and backend over the images [s]."""
    parts = pipeline.open_pipeline(cfg)
    t0 = time.perf_counter()
    edges = [e for img, t in zip(images, times) for e in parts.tracker.process(img, t)[1]]
    parts.backend.solve(len(images), edges, times=times, imu=parts.imu)
    return time.perf_counter() - t0


def orbslam3_seconds(images, times, vocabulary: Path, settings: Path, folder: Path) -> float:
    """Every image through ORB-SLAM3's child process [s] (its start and vocabulary load excluded)."""
    from eas_vo.slam.process import OrbSlam3Process

    slam = OrbSlam3Process(vocabulary, settings, folder / "slam.log")
    try:
        t0 = time.perf_counter()
        for image, t in zip(images, times):
            slam.track(image, t)
        return time.perf_counter() - t0
    finally:
        slam.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dataset", default="synthetic:walk")
    parser.add_argument("--frontend", default="original")
    parser.add_argument("--vocabulary", type=Path)
    parser.add_argument(
        "--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="a config override, as eas-vo run --set"
    )
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from eas_vo.slam.export import settings_yaml
    from eas_vo.slam.process import find_vocabulary, require_extra
    from eas_vo.slam.train import train_vocabulary

    require_extra()
    base = {"dataset": args.dataset, "frontend": args.frontend}
    configs = {name: config.resolve(name, base, args.set) for name in ("paper", "best")}
    images, times = frontend_images(configs["paper"])
    span = float(times[-1] - times[0])
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        vocabulary = args.vocabulary
        if vocabulary is None:
            vocabulary = folder / "bench.voc.txt"
            train_vocabulary(configs["paper"], vocabulary, 10, 4)
        vocabulary = find_vocabulary(str(vocabulary))
        parts = pipeline.open_pipeline(configs["paper"])
        settings = folder / "settings.yaml"
        settings.write_text(settings_yaml(parts.dataset.camera, (len(times) - 1) / span))
        runs = {"ORB-SLAM3 (monocular)": lambda: orbslam3_seconds(images, times, vocabulary, settings, folder)}
        for name, cfg in configs.items():
            runs[f"eas-vo --config {name} ({cfg.run.tracker}+{cfg.run.backend})"] = lambda cfg=cfg: eas_vo_seconds(
                cfg, images, times
            )
        print(f"{len(images)} {args.frontend} images of {args.dataset} ({span:.1f} s), best of {args.repeat}:")
        for label, timed in runs.items():
            seconds = min(timed() for _ in range(args.repeat))
            print(f"  {label:45s} {len(images) / seconds:8.1f} frames/s  real-time factor {span / seconds:6.1f}")


if __name__ == "__main__":
    main()
