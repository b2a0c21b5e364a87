"""Event throughput of the event frontends on the embedded default sequence, and of
dv-processing's SITS on the same events in the same run.

  slice : the stream cut into consecutive slices of N events (Eq. 1), events/s aggregated;
  eas   : per frame, the N events after it aggregated, smoothed and fused (Eq. 2);
  ts/sits: the whole stream consumed incrementally, one render per frame.

    python benchmarks/bench_frontends.py [--sits-events 2000000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eas_vo import config
from eas_vo.frontends.events import EasFrontend, event_slice
from eas_vo.frontends.surfaces import SitsConfig, SitsFrontend, TsFrontend
from eas_vo.registry import open_dataset


def best_of(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", default="synthetic:default")
    parser.add_argument(
        "--sits-events", type=int, default=2_000_000, help="events for the SITS comparison with dv-processing"
    )
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    dataset = open_dataset(args.dataset)
    events = np.asarray(dataset.events())  # in memory: we time the frontends, not the disk
    samples = list(dataset.samples())
    cam = dataset.camera
    n = config.resolve(None, {"frontend": "slice"}).frontend.n
    print(f"{args.dataset}: {len(events):,} events, {len(samples)} frames (best of {args.repeat})")

    def slices():
        for start in range(0, len(events), n):
            event_slice(events[start : start + n], n, cam.width, cam.height)

    t = best_of(slices, args.repeat)
    print(f"  slice  {len(events) / t / 1e6:8.1f} M events/s   (N = {n}, every event once)")

    eas = EasFrontend(config.resolve(None, {"frontend": "eas"}).frontend, cam)
    t = best_of(lambda: [eas(s) for s in samples], args.repeat)
    aggregated = sum(min(n, len(s.events) - s.event_index) for s in samples)
    print(f"  eas    {aggregated / t / 1e6:8.1f} M events/s   ({len(samples) / t:.0f} frames/s, N = {n} per frame)")

    def stream(frontend):
        frontend.reset()
        for s in samples:
            frontend(s)
        frontend.consume(events[samples[-1].event_index :])

    for cls in (TsFrontend, SitsFrontend):
        frontend = cls(config.resolve(None, {"frontend": cls.name}).frontend, cam)
        stream(frontend)  # load the compiled kernels
        t = best_of(lambda: stream(frontend), args.repeat)
        print(f"  {cls.name:6s} {len(events) / t / 1e6:8.1f} M events/s   (whole stream, {len(samples)} renders)")

    subset = events[: args.sits_events]
    for dv_window in (False, True):
        ours = SitsFrontend(SitsConfig(r=4, dv_compatible=dv_window), cam)
        t_ours = best_of(lambda: (ours.reset(), ours.consume(subset)), args.repeat)
        label = "sits (dv window)" if dv_window else "sits (paper window)"
        print(f"  {label:22s} {len(subset) / t_ours / 1e6:6.1f} M events/s on the first {len(subset):,} events")
    try:
        import dv_processing as dv
    except ImportError:
        print("  dv-processing SITS: not installed (pip install dv-processing)")
        return
    store = dv.EventStore()
    for ts, x, y, p in zip(
        (subset["t"] * 1e6).astype(np.int64).tolist(), subset["x"].tolist(), subset["y"].tolist(), subset["p"].tolist()
    ):
        store.push_back(ts, x, y, bool(p))

    def peer():
        surface = dv.SpeedInvariantTimeSurface((cam.width, cam.height))
        surface.accept(store)

    t_dv = best_of(peer, args.repeat)
    print(
        f"  dv-processing SITS     {len(subset) / t_dv / 1e6:6.1f} M events/s on the same events "
        f"(ours with its window: {t_dv / t_ours:.2f}x its throughput)"
    )


if __name__ == "__main__":
    main()
