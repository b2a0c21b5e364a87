"""Prophesee decoding throughput: EVT 3.0, EVT 2.0 and `.dat` files of --events random events on
a 1280x720 sensor, written here (EVT words only where the time, row or pixel changes: a
spec-valid stream without vectors), decoded by

  - eas-vo's decoder alone (eas_vo.eventfile.prophesee, 4 MiB blocks; a `.dat` has none);
  - the `prophesee` reader's first read (decode, validate, into the event cache) and cached read;
  - expelliarmus (Wizard.read: the whole file into memory), the peer tonic reads these files with.

Prints M events/s for each, the best of --repeat runs. No figure is quoted in the docs: run it.

    python benchmarks/bench_prophesee.py [--events 10000000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

WIDTH, HEIGHT = 1280, 720


def random_events(n: int, seed: int = 0) -> np.ndarray:
    """n events over n / 20 M s (20 M events/s), sorted by time."""
    rng = np.random.default_rng(seed)
    ev = np.empty(n, [("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    ev["t"] = np.sort(rng.integers(0, max(1, n // 20), n))
    ev["x"], ev["y"], ev["p"] = rng.integers(0, WIDTH, n), rng.integers(0, HEIGHT, n), rng.integers(0, 2, n)
    return ev


def interleave(columns: list[tuple[np.ndarray, np.ndarray]], dtype) -> np.ndarray:
    """Per event, the words of `columns` ((word, present) pairs, in order) where present."""
    words = np.stack([w for w, _ in columns], axis=1).astype(dtype)
    present = np.stack([m for _, m in columns], axis=1)
    return words[present]


def evt3_words(ev: np.ndarray) -> np.ndarray:
    t, y = ev["t"], ev["y"].astype(np.int64)
    first = np.r_[True, np.zeros(len(ev) - 1, bool)]
    new_high = first | (np.diff(t >> 12, prepend=0) != 0)
    new_low = new_high | (np.diff(t, prepend=-1) != 0)
    new_row = new_low | (np.diff(y, prepend=-1) != 0)
    return interleave(
        [
            (0x8000 | (t >> 12) & 0xFFF, new_high),
            (0x6000 | t & 0xFFF, new_low),
            (y, new_row),
            (0x2000 | ev["p"].astype(np.int64) << 11 | ev["x"], np.ones(len(ev), bool)),
        ],
        np.uint16,
    )


def evt2_words(ev: np.ndarray) -> np.ndarray:
    t = ev["t"]
    new_high = np.diff(t >> 6, prepend=-1) != 0
    cd = ev["p"].astype(np.int64) << 28 | (t & 63) << 22 | ev["x"].astype(np.int64) << 11 | ev["y"]
    return interleave([(0x8 << 28 | (t >> 6) & 0xFFFFFFF, new_high), (cd, np.ones(len(ev), bool))], np.uint32)


def write_files(folder: Path, ev: np.ndarray) -> dict[str, Path]:
    header = f"% format {{}};height={HEIGHT};width={WIDTH}\n% end\n"
    files = {"evt3": folder / "events_evt3.raw", "evt2": folder / "events_evt2.raw", "dat": folder / "events.dat"}
    files["evt3"].write_bytes(header.format("EVT3").encode() + evt3_words(ev).astype("<u2").tobytes())
    files["evt2"].write_bytes(header.format("EVT2").encode() + evt2_words(ev).astype("<u4").tobytes())
    records = np.empty((len(ev), 2), "<u4")
    records[:, 0] = ev["t"]
    records[:, 1] = ev["x"].astype(np.uint32) | ev["y"].astype(np.uint32) << 14 | ev["p"].astype(np.uint32) << 28
    dat_header = f"% Data file containing CD events.\n% Version 2\n% Width {WIDTH}\n% Height {HEIGHT}\n".encode()
    files["dat"].write_bytes(dat_header + bytes([12, 8]) + records.tobytes())
    return files


def best(fn, repeat: int, setup=None) -> tuple[float, int]:
    """(fastest time [s], events fn returned) over `repeat` runs, `setup` before each."""
    times, count = [], 0
    for _ in range(repeat):
        if setup:
            setup()
        start = time.perf_counter()
        count = fn()
        times.append(time.perf_counter() - start)
    return min(times), count


def decode_only(path: Path, fmt: str) -> int:
    from eas_vo.datasets.prophesee import BLOCK_BYTES, read_header
    from eas_vo.eventfile.prophesee import DECODERS

    decoder, count = DECODERS[fmt](WIDTH, HEIGHT), 0
    with open(path, "rb") as fh:
        fh.seek(read_header(path).data_offset)
        while block := fh.read(BLOCK_BYTES):
            count += len(decoder.decode(np.frombuffer(block, np.uint8)).t_ns)
    return count


def reader(path: Path) -> int:
    from eas_vo.datasets.prophesee import PropheseeDataset

    events = PropheseeDataset(path).events()
    return len(events) if events["t"][-1] >= 0 else 0  # every page read


def expelliarmus_read(path: Path, encoding: str) -> int:
    from expelliarmus import Wizard

    return len(Wizard(encoding=encoding).read(path))


def clear_cache(cache: Path) -> None:
    for path in cache.rglob("*"):
        if path.is_file() and path.suffix in (".ev", ".npz", ".warnings"):
            path.unlink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--events", type=int, default=10_000_000)
    parser.add_argument("--repeat", type=int, default=3, help="runs per row; the best is reported")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        os.environ["EAS_VO_CACHE_DIR"] = str(cache)  # a private event cache, gone after
        files = write_files(Path(tmp), random_events(args.events))
        for fmt in ("EVT3", "EVT2"):
            decode_only(files[fmt.lower()], fmt)  # compile (or load) the kernels before timing
        print(f"{args.events} events, {WIDTH}x{HEIGHT} sensor; M events/s, best of {args.repeat}")
        for name, path in files.items():
            rows = []
            if name != "dat":
                rows.append(("eas-vo decoder", *best(lambda: decode_only(path, name.upper()), args.repeat)))
            rows.append(
                ("eas-vo reader, first read", *best(lambda: reader(path), args.repeat, lambda: clear_cache(cache)))
            )
            rows.append(("eas-vo reader, cached", *best(lambda: reader(path), args.repeat)))
            rows.append(("expelliarmus", *best(lambda: expelliarmus_read(path, name), args.repeat)))
            size_mb = path.stat().st_size / 1e6
            for label, seconds, count in rows:
                print(
                    f"  {name:5s} {label:28s} {count / seconds / 1e6:8.1f} M events/s  ({size_mb:.0f} MB in {seconds:.3f} s)"
                )


if __name__ == "__main__":
    main()
