"""Throughput of a whole run: by default eas-vo run's (eas + klt + chain on the embedded
default sequence), with --config that file's plugins, each replaced where a flag names another.

Prints frames/s and the real-time factor (sequence duration / processing time) of a
whole run, serial (--threads 1) and concurrent (a thread per core), alternated, and their
ratio; the share of a serial run spent inside OpenCV's functions and numba's kernels (what
no change to the Python around them can remove on one core); where the time goes (loading, frontend, tracker, backend); for a tracker that reads events, the events/s it processes; for cmax, its objective's evaluations/s beside a plain
numpy version of the same kernel.

    python benchmarks/bench_pipeline.py [--config FILE] [--dataset SPEC] [--frontend F] [--tracker T]
                                        [--backend B] [--set KEY=VALUE] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eas_vo import concurrency, config, pipeline, registry


def stage_times(cfg) -> dict:
    """Seconds spent in each stage over one pass of the sequence."""
    rc = cfg.run
    t0 = time.perf_counter()
    parts = pipeline.open_pipeline(cfg)
    samples = list(parts.dataset.samples(rc.start_s, rc.duration_s))
    t1 = time.perf_counter()
    images = [parts.frontend(s) if parts.frontend.makes_images else None for s in samples]
    t2 = time.perf_counter()
    events = (lambda s: {"sample": s}) if parts.tracker.needs_events else (lambda s: {})
    edges = [e for img, s in zip(images, samples) for e in parts.tracker.process(img, s.t, **events(s))[1]]
    t3 = time.perf_counter()
    times = np.array([s.t for s in samples])
    parts.backend.solve(len(samples), edges, times=times, imu=parts.imu)
    t4 = time.perf_counter()
    n = getattr(cfg.frontend, "n", 0)
    n_events = sum(min(n, len(s.events) - s.event_index) for s in samples)
    tracker_events = sum(len(s.events_since_previous) for s in samples) if parts.tracker.needs_events else 0
    return {
        "load": t1 - t0,
        "frontend": t2 - t1,
        "tracker": t3 - t2,
        "backend": t4 - t3,
        "frames": len(samples),
        "events": n_events,
        "tracker_events": tracker_events,
    }


def contrast_evaluations(cfg, repeat: int) -> None:
    """cmax's objective on one window of the dataset (tracker.window_events events from its
    middle): evaluations per second of the compiled kernel (value; value and gradient; the
    same with the four quadrants' images, as at the optimum) beside the plain numpy version of
    the same value (trackers.contrast.variance_numpy)."""
    from eas_vo.trackers.cmax import CmaxTracker
    from eas_vo.trackers.contrast import Contrast, variance_numpy

    dataset = registry.open_dataset(cfg.run.dataset, cfg.dataset)
    events = dataset.events()
    n = cfg.tracker.window_events
    window = events[max(0, len(events) // 2 - n // 2) :][:n]
    tracker = CmaxTracker(cfg.tracker, dataset.camera)
    xy = tracker._bearing[window["y"].astype(np.intp), window["x"].astype(np.intp)]
    dt = window["t"] - 0.5 * (window["t"][0] + window["t"][-1])
    contrast = Contrast(xy, dt, tracker._grid, cfg.tracker.sigma_px)
    omega = np.radians([20.0, -40.0, 10.0])
    contrast.value_and_gradient(omega)  # compiled outside the timing
    rows = (
        ("numba value", lambda: contrast.value(omega), 50),
        ("numba value+gradient", lambda: contrast.value_and_gradient(omega), 50),
        ("numba + quadrants", lambda: contrast.with_quadrants(omega), 50),
        ("numpy value", lambda: variance_numpy(xy, dt, omega, tracker._grid, cfg.tracker.sigma_px), 5),
    )
    print(f"cmax objective on {len(window):,} events ({dataset.camera.width}x{dataset.camera.height}):")
    for label, fn, count in rows:
        seconds = min(_timed(lambda: [fn() for _ in range(count)]) for _ in range(repeat)) / count
        print(f"  {label:21s} {1 / seconds:8.1f} evaluations/s  ({len(window) / seconds / 1e6:6.1f} M events/s)")


def kernel_share(cfg) -> tuple[float, dict]:
    """Wall time [s] of one serial run (--threads 1), and of it the seconds spent inside
    OpenCV's functions (called as cv2.NAME) and inside numba-compiled kernels called from
    Python (eas-vo's module-level ones), each wrapped with a timer for this run only. Run it
    after the same configuration ran once: every kernel is compiled, so none is compiled
    against a wrapper."""
    import sys
    import types

    import cv2
    from numba.core.registry import CPUDispatcher

    spent = {"OpenCV": 0.0, "numba": 0.0}

    def timer(fn, kind):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[kind] += time.perf_counter() - t0

        return timed

    originals = [(cv2, name, fn) for name, fn in vars(cv2).items() if isinstance(fn, types.BuiltinFunctionType)]
    originals += [
        (module, name, obj)
        for module in list(sys.modules.values())
        if getattr(module, "__name__", "").startswith("eas_vo")
        for name, obj in list(vars(module).items())
        if isinstance(obj, CPUDispatcher)
    ]
    threads = concurrency.threads()
    try:
        for module, name, fn in originals:
            setattr(module, name, timer(fn, "OpenCV" if module is cv2 else "numba"))
        concurrency.set_threads(1)
        elapsed = pipeline.run(cfg).metrics["elapsed_s"]
    finally:
        concurrency.set_threads(threads)
        for module, name, fn in originals:
            setattr(module, name, fn)
    return elapsed, spent


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    for kind in ("dataset", "frontend", "tracker", "backend"):
        parser.add_argument(f"--{kind}", help=f"the {kind} (default: the config's, else eas-vo run's)")
    parser.add_argument(
        "--config", help="a config file or bundled name (its [run] plugins unless the flags name others)"
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="a config override, as eas-vo run --set"
    )
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    chosen = {"dataset": args.dataset, "frontend": args.frontend, "tracker": args.tracker, "backend": args.backend}
    cfg = config.resolve(args.config, chosen, args.set)
    rc = cfg.run
    registry.open_dataset(rc.dataset).events()  # simulate and cache outside the timing

    cores = concurrency.threads()
    runs: dict[int, list[dict]] = {1: [], cores: []}
    for _ in range(args.repeat):  # alternated: the machine's drift touches both alike
        for threads in runs:
            concurrency.set_threads(threads)
            runs[threads].append(pipeline.run(cfg).metrics)
    concurrency.set_threads(cores)
    fastest = {threads: min(ms, key=lambda m: m["elapsed_s"]) for threads, ms in runs.items()}
    best = fastest[cores]
    print(
        f"{rc.frontend}+{rc.tracker}+{rc.backend} on {rc.dataset}: {best['frames']} frames, {best['sequence_s']:.2f} s of data"
    )
    for threads, m in fastest.items():
        label = "serial (--threads 1)" if threads == 1 else f"concurrent ({threads} threads)"
        print(
            f"  whole run, {label:24s} best of {args.repeat}: {m['elapsed_s']:.2f} s, "
            f"{m['frames_per_s']:.1f} frames/s, real-time factor {m['realtime_factor']:.2f}x"
        )
    if cores > 1:
        print(f"  concurrent / serial: {fastest[cores]['frames_per_s'] / fastest[1]['frames_per_s']:.2f}x")
    elapsed, inside = kernel_share(cfg)
    floor = sum(inside.values())
    print(
        f"  inside compiled kernels, serial run of {elapsed:.2f} s: "
        + ", ".join(f"{kind} {100 * s / elapsed:.0f} %" for kind, s in inside.items())
        + f": {100 * floor / elapsed:.0f} %, a floor of {floor:.2f} s ({best['frames'] / max(floor, 1e-9):.0f} frames/s) on one core"
    )
    stages = min((stage_times(cfg) for _ in range(args.repeat)), key=lambda s: s["frontend"] + s["tracker"])
    total = sum(stages[k] for k in ("load", "frontend", "tracker", "backend"))
    for k in ("load", "frontend", "tracker", "backend"):
        print(
            f"  {k:9s} {stages[k]:7.3f} s  ({100 * stages[k] / total:4.1f} %)  {stages['frames'] / max(stages[k], 1e-9):9.1f} frames/s"
        )
    if stages["events"]:
        print(
            f"  frontend: {stages['events'] / max(stages['frontend'], 1e-9) / 1e6:.1f} M events/s aggregated "
            f"({stages['events']:,} events in {stages['frames']} slices)"
        )
    if stages["tracker_events"]:
        print(
            f"  tracker: {stages['tracker_events'] / max(stages['tracker'], 1e-9) / 1e6:.2f} M events/s "
            f"({stages['tracker_events']:,} events); the whole run: "
            + ", ".join(
                f"{stages['tracker_events'] / m['elapsed_s'] / 1e6:.2f} M events/s {'serial' if t == 1 else 'concurrent'}"
                for t, m in fastest.items()
            )
        )
    unaccounted = fastest[cores]["elapsed_s"] - total
    if unaccounted > 0.25 * fastest[cores]["elapsed_s"]:
        print(
            f"  the stages time one tracking; the run took {unaccounted:.2f} s more: the frames tracked again "
            "without the gyro, which the images could not check (eas_vo.imu.policy.assess)"
        )
    print(f"  APE {best.get('ape_mean_rad', np.nan):.4f} rad, NC {best['nc_mean']:.1f}")
    if rc.tracker == "cmax":
        contrast_evaluations(cfg, args.repeat)

    result = pipeline.run(cfg)
    imu = pipeline.open_pipeline(cfg).imu  # as the run gives it (the gyro fused where configured)
    n = len(result.t)
    print(f"backends on the same {len(result.edges)} edges ({n} frames):")
    for name, changes in (("chain", []), ("gtsam", ["backend.mode=batch"]), ("gtsam", ["backend.mode=online"])):
        bcfg = config.resolve(args.config, {**chosen, "backend": name}, changes)
        backend = registry.get("backends", name)(bcfg.backend)
        seconds = min(
            _timed(lambda: backend.solve(n, result.edges, times=result.t, imu=imu)) for _ in range(args.repeat)
        )
        label = name + (f" ({changes[0].split('=')[1]})" if changes else "")
        print(
            f"  {label:16s} {1e3 * seconds / n:7.3f} ms/frame  (+{100 * seconds / best['elapsed_s']:5.1f} % of the whole run)"
        )


if __name__ == "__main__":
    main()
