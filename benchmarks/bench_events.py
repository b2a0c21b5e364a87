"""Event loading throughput on a 20-million-event `events.txt` made by the simulator.

Prints, each stage in its own process (so peak memory is its own):
  - first parse (text -> binary cache) events/s and MB/s, beside pandas.read_csv (C engine)
    on the same file;
  - cached load: map the cache and read every event, events/s;
  - a 1 s window of the cached stream through the pipeline's sample views: bytes touched;
  - ROS 2 bags (sqlite3 and mcap, dvs_msgs/msg/EventArray of 5000 events) holding the first
    --bag-events of the same stream: the rosbag2 reader's first read (decode, validate, cache)
    and cached read, events/s, beside rosbags' plain iteration over the same file (raw bytes
    only, and deserialised to messages).

    python benchmarks/bench_events.py [--events 20000000] [--bag-events 2000000]
"""

from __future__ import annotations

import argparse
import io
import json
import resource
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
    from eas_vo.io import cache_folder
    from eas_vo.registry import open_dataset

    bench = cache_folder("bench", BENCH_ABOUT)
    path = bench / f"events_{n_events}.txt"
    if path.exists():
        return path
    duration = 25.0
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


def make_bag(text: Path, n_events: int, storage: str) -> Path:
    """The first n_events of `text` as a rosbag2 folder (camera info and events only)."""
    import shutil

    from eas_vo.datasets.rosbag2 import write_bag2
    from eas_vo.eventfile import file_identity, load_event_text
    from eas_vo.io import cache_folder
    from eas_vo.plugins import Dataset
    from eas_vo.types import CameraModel

    folder = cache_folder("bench", BENCH_ABOUT) / f"ros2_{storage}_{n_events}"
    if (folder / "metadata.yaml").exists():
        return folder

    class Stream(Dataset):
        def __init__(self):
            self.camera = CameraModel.from_calib([200.0, 200.0, 120.0, 90.0], 240, 180)
            self._events = load_event_text(lambda: open(text, "rb"), file_identity(text), str(text), 240, 180)[:n_events]

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
    import os

    from eas_vo.datasets.rosbag2 import Rosbag2Dataset, event_typestore

    out = {"stage": name, "size_mb": sum(f.stat().st_size for f in bag.iterdir()) / 1e6}

    def read_all():  # open, then read every byte of every record once
        events = Rosbag2Dataset(bag).events()
        return float(events.view(np.uint8).sum(dtype=np.uint64)), len(events)

    if name == "ros2_first":
        def first():
            with tempfile.TemporaryDirectory() as cache:
                os.environ["EAS_VO_CACHE_DIR"] = cache
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
                    n += len(store.deserialize_cdr(raw, conn.msgtype).events) if name == "rosbags_messages" else len(raw)
            return n

        out["seconds"], n = timed(iterate, repeat)
        out["events"] = n if name == "rosbags_messages" else Rosbag2Dataset(bag).events().shape[0]
    return out


def timed(fn, repeat: int) -> tuple[float, object]:
    """Best wall time of `repeat` calls (the machine is shared: the minimum is the signal)."""
    best, result = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def stage(name: str, path: Path, repeat: int) -> dict:
    from eas_vo.eventfile import build_cache, convert_text_to_cache, file_identity, load_event_text
    from eas_vo.types import search_times

    size_mb = path.stat().st_size / 1e6
    out = {"stage": name, "size_mb": size_mb}
    if name == "pandas":
        import pandas as pd

        def parse():
            return pd.read_csv(path, sep=" ", header=None, names=["t", "x", "y", "p"], engine="c",
                               dtype={"t": np.float64, "x": np.uint16, "y": np.uint16, "p": np.int8})

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
            with tempfile.TemporaryDirectory() as tmp, open(path, "rb") as fh:
                fill = lambda f: convert_text_to_cache(fh, str(path), f, 240, 180)  # noqa: E731
                return len(build_cache(Path(tmp) / "e.ev", fill, max_events=path.stat().st_size // 8 + 1))

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


ROS2_STAGES = {"ros2_first": "eas-vo first read (validated, cached)", "ros2_cached": "eas-vo cached read (open + map)",
               "rosbags_raw": "rosbags iteration, raw bytes", "rosbags_messages": "rosbags iteration, deserialised"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--events", type=int, default=20_000_000)
    parser.add_argument("--bag-events", type=int, default=2_000_000, help="events in the ROS 2 bags")
    parser.add_argument("--repeat", type=int, default=3, help="runs per stage; the best is reported")
    parser.add_argument("--stage", help=argparse.SUPPRESS)
    parser.add_argument("--path", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stage:
        run = ros2_stage if args.stage in ROS2_STAGES else stage
        print(json.dumps(run(args.stage, Path(args.path), args.repeat)))
        return
    path = make_file(args.events)
    results = {}
    for name in ("pandas", "parse", "parse_to_cache", "cached", "window"):
        out = subprocess.run([sys.executable, __file__, "--stage", name, "--path", str(path), "--repeat", str(args.repeat)],
                             capture_output=True, text=True, check=True)
        results[name] = json.loads(out.stdout.strip().splitlines()[-1])
    size = results["parse"]["size_mb"]
    print(f"{path.name}: {results['parse']['events']:,} events, {size:.0f} MB of text")
    for name, label in (("pandas", "pandas.read_csv (C engine)"), ("parse", "eas-vo parse (validated)"),
                        ("parse_to_cache", "eas-vo parse + cache write")):
        r = results[name]
        print(f"  {label:30s} {r['events'] / r['seconds'] / 1e6:7.1f} M events/s  {size / r['seconds']:7.1f} MB/s  "
              f"peak RSS {r['peak_rss_mb']:7.0f} MB")
    for name in ("parse", "parse_to_cache"):
        print(f"  {name} vs pandas: {results['pandas']['seconds'] / results[name]['seconds']:.2f}x")
    print(f"  (best of {args.repeat} each; excluded: eas-vo's one-time kernel load {results['parse']['jit_load_s']:.2f} s, pandas' import)")
    r = results["cached"]
    print(f"  cached load (map + read all)  {r['events'] / r['seconds'] / 1e6:7.1f} M events/s  "
          f"RSS growth {r['rss_growth_mb']:.0f} MB = {r['rss_growth_mb'] * 1e6 / r['events']:.1f} B/event")
    print(f"  cached load (map + read every timestamp) {r['events'] / r['times_seconds'] / 1e6:7.1f} M events/s")
    r = results["window"]
    print(f"  1 s window of the cached stream: {r['events']:,} events in {r['seconds'] * 1e3:.1f} ms, "
          f"RSS growth {r['rss_growth_mb']:.0f} MB = {r['rss_growth_mb'] * 1e6 / max(r['events'], 1):.1f} B/event in the window")
    for storage in ("sqlite3", "mcap"):
        bag = make_bag(path, args.bag_events, storage)
        rows = {}
        for name in ROS2_STAGES:
            out = subprocess.run([sys.executable, __file__, "--stage", name, "--path", str(bag), "--repeat", str(args.repeat)],
                                 capture_output=True, text=True, check=True)
            rows[name] = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"ROS 2 bag, {storage}: {rows['ros2_first']['events']:,} events (dvs_msgs/msg/EventArray), "
              f"{rows['ros2_first']['size_mb']:.0f} MB")
        for name, label in ROS2_STAGES.items():
            r = rows[name]
            print(f"  {label:40s} {r['events'] / r['seconds'] / 1e6:7.2f} M events/s")


if __name__ == "__main__":
    main()
