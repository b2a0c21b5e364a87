"""Event loading throughput on a 20-million-event `events.txt` made by the simulator.

Prints, each stage in its own process (so peak memory is its own):
  - first parse (text -> binary cache) events/s and MB/s, beside pandas.read_csv (C engine)
    on the same file;
  - cached load: map the cache and read every event, events/s;
  - a 1 s window of the cached stream through the pipeline's sample views: bytes touched;
  - the same events as an AEDAT4 (written by dv-processing, as DV records: LZ4): the aedat4
    reader's first read (validated, into the cache) and cached read, beside dv-processing's own
    batch reading of the file;
  - the same events as an MVSEC HDF5 file (davis/left/events, x y t p float64 rows): the
    `mvsec` reader's first read (validated, into the cache) and cached read, beside h5py
    reading the whole array into memory;
  - ROS 2 bags (sqlite3 and mcap, dvs_msgs/msg/EventArray of 5000 events) holding the first
    --bag-events of the same stream: the rosbag2 reader's first read (decode, validate, cache)
    and cached read, events/s, beside rosbags' plain iteration over the same file (raw bytes
    only, and deserialised to messages).

    python benchmarks/bench_events.py [--events 20000000] [--bag-events 2000000] [--only text|aedat4|mvsec|ros2_sqlite3|ros2_mcap]
                                      [--alternate 8]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


#: What the benchmarks keep in the cache's `bench` part (eas-vo cache shows it).
BENCH_ABOUT = "inputs of benchmarks/bench_events.py and bench_memory.py"


def make_file(n_events: int) -> Path:
    """The first n_events of a simulated sequence long enough to hold them, as events.txt."""
    from eas_vo.datasets.simulator import SimConfig, simulate
    from eas_vo.eventfile import write_events_text
    from eas_vo.io.cache import cache_folder
    from eas_vo.registry import open_dataset

    bench = cache_folder("bench", BENCH_ABOUT)
    path = bench / f"events_{n_events}.txt"
    if path.exists():
        return path
    duration = 25.0 * min(1.0, n_events / 20e6)  # about 0.8 M events/s
    while True:
        folder = bench / f"sim_{duration:g}s"
        if not (folder / "images.txt").exists():
            print(f"simulating {duration:g} s ...", file=sys.stderr)
            simulate(SimConfig(duration_s=duration, seed=11), folder)
        events = open_dataset(str(folder)).events()
        if len(events) >= n_events:
            break
        duration *= 1.2 * n_events / len(events)
    write_events_text(path, np.asarray(events[:n_events]), 240, 180)
    return path


def make_aedat4(text: Path) -> Path:
    """The events of the events.txt `text` as an events-only AEDAT4 written by dv-processing
    (DV's own writer, LZ4-compressed packets as DV records them), with a calib.txt beside it."""
    import dv_processing as dv

    from eas_vo.eventfile import file_identity, load_event_text
    from eas_vo.io.atomic import write_text_atomic

    path = text.with_suffix(".aedat4")
    write_text_atomic(path.with_name("calib.txt"), "200 200 120 90 0 0 0 0 0\n")
    if path.exists():
        return path
    events = load_event_text(lambda: open(text, "rb"), file_identity(text), str(text), 240, 180)
    with tempfile.TemporaryDirectory(dir=path.parent) as folder:  # the writer wants a new file named *.aedat4
        tmp = Path(folder) / path.name
        writer = dv.io.MonoCameraWriter(str(tmp), dv.io.MonoCameraWriter.EventOnlyConfig("bench", (240, 180)))
        for start in range(0, len(events), 100_000):
            chunk = events[start : start + 100_000]
            store = dv.EventStore()
            for t, x, y, p in zip(
                np.round(chunk["t"] * 1e6).astype(np.int64).tolist(),
                chunk["x"].tolist(),
                chunk["y"].tolist(),
                chunk["p"].tolist(),
            ):
                store.push_back(t, x, y, p > 0)
            writer.writeEvents(store)
        del writer  # closing writes the file's index
        os.replace(tmp, path)
    return path


def aedat4_reads(path: Path) -> tuple:
    """(dv-processing's batch reading of the AEDAT4, giving the event count; the aedat4 reader's
    events, opened through the cache)."""
    import dv_processing as dv

    from eas_vo.datasets.aedat4 import Aedat4Config, Aedat4Dataset

    config = Aedat4Config(calibration=str(path.with_name("calib.txt")))

    def library():
        recording, n = dv.io.MonoCameraRecording(str(path)), 0
        while (batch := recording.getNextEventBatch()) is not None:
            n += len(batch.numpy())
        return n

    return library, lambda: Aedat4Dataset(path, config).events()


#: A pinhole 240x180 camera (the simulator's size) for the MVSEC file, as a kalibr camchain.
BENCH_CAMCHAIN = """cam0:
  camera_model: pinhole
  intrinsics: [200.0, 200.0, 120.0, 90.0]
  distortion_model: none
  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]
  resolution: [240, 180]
"""


def make_mvsec_file(text: Path) -> Path:
    """The events of `text` as an MVSEC NAME_data.hdf5 (davis/left/events only), with a camchain beside it."""
    import h5py

    from eas_vo.io.atomic import atomic_path, write_text_atomic

    path = text.with_name(text.stem + "_data.hdf5")
    write_text_atomic(text.with_name(text.stem + "_camchain.yaml"), BENCH_CAMCHAIN)
    if path.exists():
        return path
    events = load_text(text)
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        dset = f.create_dataset("davis/left/events", shape=(len(events), 4), dtype=np.float64)
        step = 1 << 20
        for start in range(0, len(events), step):
            chunk = events[start : start + step]
            dset[start : start + len(chunk)] = np.column_stack(
                [chunk["x"], chunk["y"], chunk["t"], np.where(chunk["p"] > 0, 1.0, -1.0)]
            )
    return path


def load_text(path: Path) -> np.ndarray:
    from eas_vo.eventfile import file_identity, load_event_text

    return load_event_text(lambda: open(path, "rb"), file_identity(path), str(path), 240, 180)


def mvsec_reads(path: Path) -> tuple:
    """(h5py reading the whole (N, 4) float64 event array into memory, unchecked, giving the
    event count; the mvsec reader's events, opened through the cache)."""
    import h5py

    from eas_vo.datasets.mvsec import MvsecConfig, MvsecDataset

    config = MvsecConfig(
        calibration=str(path.with_name(path.name.replace("_data.hdf5", "_camchain.yaml"))), width=240, height=180
    )

    def library():
        with h5py.File(path, "r") as f:
            return len(f["davis/left/events"][()])

    return library, lambda: MvsecDataset(path, config).events()


#: Each format with a library of its own: how its two reads are made.
READS = {"aedat4": aedat4_reads, "mvsec": mvsec_reads}


def format_stage(name: str, path: Path, repeat: int, out: dict) -> None:
    """One of FORMAT_library (the library's own read), FORMAT_first (eas-vo's first read: open,
    check and cache every event, into an empty cache each time), FORMAT_cached (open, map, read
    every byte of every record) and FORMAT_alternate (the library's read and the first read in
    turn, `repeat` times each: best and median of both)."""
    fmt, kind = name.split("_", 1)
    library, open_events = READS[fmt](path)
    first = lambda: len(open_events())  # noqa: E731
    if kind == "library":
        out["seconds"], out["events"] = timed(library, repeat)
    elif kind in ("first", "alternate"):
        # Untimed before each first read: the previous run's cache removed, as the library's
        # array of its previous run is freed before the next. Kept, each run wrote 250 MB more
        # into new pages while the earlier runs' waited to be written back: up to 3x slower (VM).
        empty_cache()
        first(), library()  # the libraries and numba's compiled kernels loaded once
        if kind == "first":
            out["seconds"], out["events"] = timed(first, repeat, setup=empty_cache)
            return
        times = {"library": [], "first": []}
        for _ in range(repeat):
            for part, read in (("library", library), ("first", first)):
                empty_cache()
                t0 = time.perf_counter()
                out["events"] = read()
                times[part].append(time.perf_counter() - t0)
        out["seconds"] = min(times["first"])
        out.update(
            {
                f"{part}_{stat}": fn(values)
                for part, values in times.items()
                for stat, fn in (("best_s", min), ("median_s", statistics.median))
            }
        )
    else:
        open_events()  # build the cache once

        def cached():
            events = open_events()
            return float(events.view(np.uint8).sum(dtype=np.uint64)), len(events)

        out["seconds"], (_, out["events"]) = timed(cached, repeat)


def make_bag(text: Path, n_events: int, storage: str) -> Path:
    """The first n_events of `text` as a rosbag2 folder (camera info and events only)."""
    import shutil

    from eas_vo.camera import CameraModel
    from eas_vo.datasets.rosbag2 import write_bag2
    from eas_vo.eventfile import file_identity, load_event_text
    from eas_vo.io.cache import cache_folder
    from eas_vo.plugins import Dataset

    folder = cache_folder("bench", BENCH_ABOUT) / f"ros2_{storage}_{n_events}"
    if (folder / "metadata.yaml").exists():
        return folder

    class Stream(Dataset):
        def __init__(self):
            self.camera = CameraModel.from_calib([200.0, 200.0, 120.0, 90.0], 240, 180)
            self._events = load_event_text(lambda: open(text, "rb"), file_identity(text), str(text), 240, 180)[
                :n_events
            ]

        def frame_times(self):
            return np.empty(0)

        def load_frame(self, k):
            return None

        def events(self):
            return self._events

    shutil.rmtree(folder, ignore_errors=True)
    write_bag2(Stream(), folder, storage)
    return folder


def ros2_stage(name: str, bag: Path, repeat: int) -> dict:
    """`ros2_first`, `ros2_cached`, `rosbags_raw` or `rosbags_messages` on a rosbag2 folder."""
    from eas_vo.datasets.rosbag2 import Rosbag2Dataset, event_typestore

    out = {"stage": name, "size_mb": sum(f.stat().st_size for f in bag.iterdir()) / 1e6}

    def read_all():  # open, then read every byte of every record once
        events = Rosbag2Dataset(bag).events()
        return float(events.view(np.uint8).sum(dtype=np.uint64)), len(events)

    if name == "ros2_first":

        def first():
            fresh_cache()
            return read_all()

        read_all()  # (numba's kernels loaded once, as for the text stages)
        out["seconds"], (_, out["events"]) = timed(first, repeat)
    elif name == "ros2_cached":
        read_all()
        out["seconds"], (_, out["events"]) = timed(read_all, repeat)
    else:
        from rosbags.rosbag2 import Reader

        store = event_typestore()

        def iterate():
            n = 0
            with Reader(bag) as reader:
                events = [c for c in reader.connections if c.topic == "/dvs/events"]
                for conn, _, raw in reader.messages(connections=events):
                    n += (
                        len(store.deserialize_cdr(raw, conn.msgtype).events) if name == "rosbags_messages" else len(raw)
                    )
            return n

        out["seconds"], n = timed(iterate, repeat)
        out["events"] = n if name == "rosbags_messages" else Rosbag2Dataset(bag).events().shape[0]
    return out


#: Where the first-read stages put a fresh cache per run; removed when the stage's process
#: ends, so that deleting a cache (not part of reading) is not timed.
FRESH_CACHES = tempfile.TemporaryDirectory(prefix="bench-caches-")


def fresh_cache() -> None:
    """Point eas-vo at a new, empty cache folder."""
    os.environ["EAS_VO_CACHE_DIR"] = tempfile.mkdtemp(dir=FRESH_CACHES.name)


def empty_cache() -> None:
    """fresh_cache(), removing the cache folder the previous call made (if any)."""
    import shutil

    previous = os.environ.get("EAS_VO_CACHE_DIR", "")
    if previous.startswith(FRESH_CACHES.name + os.sep):
        shutil.rmtree(previous)
    fresh_cache()


def timed(fn, repeat: int, setup=None) -> tuple[float, object]:
    """Best wall time of `repeat` calls (the machine is shared: the minimum is the signal);
    `setup()`, if given, runs untimed before each."""
    best, result = float("inf"), None
    for _ in range(repeat):
        if setup is not None:
            setup()
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def stage(name: str, path: Path, repeat: int) -> dict:
    from eas_vo.eventfile import build_cache, convert_text_to_cache, file_identity, load_event_text
    from eas_vo.types import search_times

    size_mb = path.stat().st_size / 1e6
    out = {"stage": name, "size_mb": size_mb}
    if name.split("_")[0] in READS:
        format_stage(name, path, repeat, out)
    elif name == "pandas":
        import pandas as pd

        def parse():
            return pd.read_csv(
                path,
                sep=" ",
                header=None,
                names=["t", "x", "y", "p"],
                engine="c",
                dtype={"t": np.float64, "x": np.uint16, "y": np.uint16, "p": np.int8},
            )

        out["seconds"], frame = timed(parse, repeat)
        out["events"] = len(frame)
    elif name in ("parse", "parse_to_cache"):
        warm = time.perf_counter()
        with open(path, "rb") as fh:  # load the compiled kernels from numba's cache (once per process)
            convert_text_to_cache(io.BytesIO(fh.readline()), str(path), io.BytesIO(), 240, 180)
        out["jit_load_s"] = time.perf_counter() - warm

        class Memory:  # keeps the validated, packed records, as pandas keeps its DataFrame
            def __init__(self):
                self.chunks = []

            def writelines(self, records):
                self.chunks.extend(np.frombuffer(data, np.uint8).copy() for data in records)

        def parse():
            with open(path, "rb") as fh:
                return convert_text_to_cache(fh, str(path), Memory(), 240, 180)

        def parse_to_cache():
            with open(path, "rb") as fh:
                fill = lambda f: convert_text_to_cache(fh, str(path), f, 240, 180)  # noqa: E731
                target = Path(tempfile.mkdtemp(dir=FRESH_CACHES.name)) / "e.ev"
                return len(build_cache(target, fill, max_events=path.stat().st_size // 8 + 1))

        out["seconds"], out["events"] = timed(parse if name == "parse" else parse_to_cache, repeat)
    else:

        def load():
            return load_event_text(lambda: open(path, "rb"), file_identity(path), str(path), 240, 180)

        load()  # build the cache once
        rss0 = peak_rss_mb()
        if name == "cached":

            def read_all():  # map, then read every byte of every record once
                events = load()
                return float(events.view(np.uint8).sum(dtype=np.uint64)), len(events)

            def read_times():  # map, then read every timestamp (what windowing and sampling use)
                events = load()
                return float(events["t"].max()), len(events)

            out["seconds"], (_, out["events"]) = timed(read_all, repeat)
            out["times_seconds"], _ = timed(read_times, repeat)
        else:

            def window():  # map, find a 1 s window, read it
                events = load()
                start = float(events["t"][0])
                lo, hi = search_times(events, [start + 1.0, start + 2.0])
                return float(events[lo:hi]["t"].sum()), int(hi - lo)

            out["seconds"], (_, out["events"]) = timed(window, repeat)
        out["rss_growth_mb"] = peak_rss_mb() - rss0
    out["peak_rss_mb"] = peak_rss_mb()
    return out


#: Each format: how its file is made from the events.txt, its stages (the library's own reader
#: first) and their labels.
ROS2_STAGES = ["rosbags_raw", "rosbags_messages", "ros2_first", "ros2_cached"]
ROS2_LABELS = [
    "rosbags iteration, raw bytes",
    "rosbags iteration, deserialised",
    "eas-vo rosbag2 first read (validated + cache write)",
    "eas-vo rosbag2 cached read (open + map)",
]
FORMATS = {
    "text": (lambda path, args: path, ["pandas", "parse", "parse_to_cache", "cached", "window"], []),
    "aedat4": (
        lambda path, args: make_aedat4(path),
        ["aedat4_library", "aedat4_first", "aedat4_cached"],
        [
            "dv-processing batch reading",
            "eas-vo aedat4 first read (validated + cache write)",
            "eas-vo aedat4 cached read (map + read all)",
        ],
    ),
    "mvsec": (
        lambda path, args: make_mvsec_file(path),
        ["mvsec_library", "mvsec_first", "mvsec_cached"],
        [
            "h5py, whole array (unchecked)",
            "eas-vo mvsec first read (validated + cache write)",
            "eas-vo mvsec cached read (map + read all)",
        ],
    ),
    "ros2_sqlite3": (lambda path, args: make_bag(path, args.bag_events, "sqlite3"), ROS2_STAGES, ROS2_LABELS),
    "ros2_mcap": (lambda path, args: make_bag(path, args.bag_events, "mcap"), ROS2_STAGES, ROS2_LABELS),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--events", type=int, default=20_000_000)
    parser.add_argument("--bag-events", type=int, default=2_000_000, help="events in the ROS 2 bags")
    parser.add_argument("--repeat", type=int, default=3, help="runs per stage; the best is reported")
    parser.add_argument("--only", choices=list(FORMATS), help="run only this format's rows")
    parser.add_argument(
        "--alternate",
        type=int,
        default=0,
        metavar="N",
        help="also alternate the library's read and the first read N times each in one process "
        "(AEDAT4, MVSEC): best and median of each, and their ratios",
    )
    parser.add_argument("--stage", help=argparse.SUPPRESS)
    parser.add_argument("--path", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stage:
        run = ros2_stage if args.stage in ROS2_STAGES else stage
        print(json.dumps(run(args.stage, Path(args.path), args.repeat)))
        return
    path = make_file(args.events)
    results = {}
    for fmt, (make, stages, _) in FORMATS.items():
        if args.only not in (None, fmt):
            continue
        source = make(path, args)
        for name in stages:
            out = subprocess.run(
                [sys.executable, __file__, "--stage", name, "--path", str(source), "--repeat", str(args.repeat)],
                capture_output=True,
                text=True,
                check=True,
            )
            results[name] = json.loads(out.stdout.strip().splitlines()[-1])
        if fmt == "text":
            print_text_rows(path, results, args.repeat)
        else:
            print_format_rows(source, results, stages, FORMATS[fmt][2], args.repeat)
        if args.alternate and fmt in READS:
            out = subprocess.run(
                [
                    sys.executable,
                    __file__,
                    "--stage",
                    f"{fmt}_alternate",
                    "--path",
                    str(source),
                    "--repeat",
                    str(args.alternate),
                ],
                capture_output=True,
                text=True,
                check=True,
            )
            r = json.loads(out.stdout.strip().splitlines()[-1])
            rate = lambda seconds: r["events"] / seconds / 1e6  # noqa: E731
            print(
                f"  alternated in one process, {args.alternate} times each: library {rate(r['library_best_s']):.1f} "
                f"(median {rate(r['library_median_s']):.1f}), first read {rate(r['first_best_s']):.1f} "
                f"(median {rate(r['first_median_s']):.1f}) M events/s; first read / library "
                f"{r['library_best_s'] / r['first_best_s']:.2f}x best, {r['library_median_s'] / r['first_median_s']:.2f}x median"
            )


def print_format_rows(source: Path, results: dict, stages: list, labels: list, repeat: int) -> None:
    r = results[stages[-1]]
    print(f"{source.name}: {r['events']:,} events, {r['size_mb']:.0f} MB")
    for name, label in zip(stages, labels):
        r = results[name]
        print(f"  {label:52s} {r['events'] / r['seconds'] / 1e6:7.1f} M events/s")
    print(f"  (best of {repeat} each)")


def print_text_rows(path: Path, results: dict, repeat: int) -> None:
    size = results["parse"]["size_mb"]
    print(f"{path.name}: {results['parse']['events']:,} events, {size:.0f} MB of text")
    for name, label in (
        ("pandas", "pandas.read_csv (C engine)"),
        ("parse", "eas-vo parse (validated)"),
        ("parse_to_cache", "eas-vo parse + cache write"),
    ):
        r = results[name]
        print(
            f"  {label:30s} {r['events'] / r['seconds'] / 1e6:7.1f} M events/s  {size / r['seconds']:7.1f} MB/s  "
            f"peak RSS {r['peak_rss_mb']:7.0f} MB"
        )
    for name in ("parse", "parse_to_cache"):
        print(f"  {name} vs pandas: {results['pandas']['seconds'] / results[name]['seconds']:.2f}x")
    print(
        f"  (best of {repeat} each; excluded: eas-vo's one-time kernel load {results['parse']['jit_load_s']:.2f} s, pandas' import)"
    )
    r = results["cached"]
    print(
        f"  cached load (map + read all)  {r['events'] / r['seconds'] / 1e6:7.1f} M events/s  "
        f"RSS growth {r['rss_growth_mb']:.0f} MB = {r['rss_growth_mb'] * 1e6 / r['events']:.1f} B/event"
    )
    print(f"  cached load (map + read every timestamp) {r['events'] / r['times_seconds'] / 1e6:7.1f} M events/s")
    r = results["window"]
    print(
        f"  1 s window of the cached stream: {r['events']:,} events in {r['seconds'] * 1e3:.1f} ms, "
        f"RSS growth {r['rss_growth_mb']:.0f} MB = {r['rss_growth_mb'] * 1e6 / max(r['events'], 1):.1f} B/event in the window"
    )


if __name__ == "__main__":
    main()
