"""MVSEC events mapped straight from the file (contiguous, unfiltered float64) and read through
h5py's blocks (every other layout) give the same cache byte for byte, the same errors naming
the same rows, and the same counted drops; files the map must not take go through h5py."""

import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.datasets import mvsec
from eas_vo.datasets.mvsec import MvsecConfig, MvsecDataset
from eas_vo.errors import DataError
from eas_vo.types import EVENT_DTYPE
from helpers import hostile_settings

WIDTH, HEIGHT = 346, 260
CAMCHAIN = """\
cam0:
  camera_model: pinhole
  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]
  distortion_model: equidistant
  intrinsics: [226.38, 226.15, 173.65, 133.73]
  resolution: [346, 260]
"""


def event_table(n: int, seed: int = 0) -> np.ndarray:
    """n MVSEC rows `x y t p` on a 346x260 sensor, times increasing from an MVSEC-like epoch [s]."""
    rng = np.random.default_rng(seed)
    t = 1_504_645_177.0 + np.cumsum(rng.uniform(0, 2e-5, n))
    return np.column_stack([rng.integers(0, WIDTH, n), rng.integers(0, HEIGHT, n), t, rng.choice([-1.0, 1.0], n)])


def write_events(path: Path, table: np.ndarray, **options) -> Path:
    """davis/left/events holding `table` (h5py's create_dataset options: dtype, chunks,
    compression...), a camchain beside it."""
    path.with_name("camchain-imucam-test.yaml").write_text(CAMCHAIN)
    with h5py.File(path, "w", **options.pop("file", {})) as f:
        f.create_dataset("davis/left/events", data=table, **options)
    return path


def read(path: Path, cache: Path, monkeypatch, mapped: bool, lenient: bool = False):
    """(events, warning lines, the cache folder's files: name -> bytes) of a first read into an
    empty cache, or the DataError's message; mapped or through h5py's blocks."""
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(cache))
    monkeypatch.setattr(mvsec, "MAP_EVENTS", mapped)
    ds = MvsecDataset(path, MvsecConfig(lenient=lenient))
    try:
        events = np.array(ds.events())
    except DataError as exc:
        return str(exc)
    files = {p.name: p.read_bytes() for p in sorted((cache / "events").iterdir()) if not p.name.startswith(".")}
    return events, ds.data_warnings(), files, ds.clock_origin_ns


def took_the_map(path: Path, monkeypatch) -> bool:
    """Whether the reader maps the events of `path` (instead of reading them with h5py)."""
    monkeypatch.setattr(mvsec, "MAP_EVENTS", True)
    ds = MvsecDataset(path)
    return ds._map_events(ds._events_dset) is not None


def expected_events(rows: np.ndarray, origin_ns: int = 0) -> np.ndarray:
    """The records of MVSEC rows, their times after the reader's clock origin [ns]."""
    ev = np.empty(len(rows), EVENT_DTYPE)
    ev["x"], ev["y"], ev["t"], ev["p"] = rows[:, 0], rows[:, 1], rows[:, 2] - origin_ns / 1e9, rows[:, 3] > 0
    return ev


@pytest.mark.parametrize(
    "options, mappable",
    [
        ({}, True),
        ({"dtype": ">f8"}, True),
        ({"file": {"userblock_size": 512}}, True),
        ({"chunks": (700, 4)}, False),
        ({"chunks": (1000, 4), "compression": "gzip", "shuffle": True}, False),
        ({"chunks": (1000, 4), "compression": "lzf", "dtype": ">f8"}, False),
    ],
)
def test_the_map_and_h5py_give_the_same_cache_byte_for_byte(tmp_path, monkeypatch, options, mappable):
    monkeypatch.setattr(mvsec, "MAP_BLOCK_ROWS", 1000)
    monkeypatch.setattr(mvsec, "BLOCK_ROWS", 1400)
    table = event_table(5000)
    table[2999, 2] = table[2998, 2] - 4e-7  # clamped: the last row of a block of the map
    table[3000, 2] = table[2999, 2] - 2e-7  # and the first of the next
    path = write_events(tmp_path / "x_data.hdf5", table, **options)
    assert took_the_map(path, monkeypatch) is mappable
    mapped = read(path, tmp_path / "a", monkeypatch, True)
    through_h5py = read(path, tmp_path / "b", monkeypatch, False)
    assert mapped[2] == through_h5py[2] and len(mapped[2]) == 1  # one cache file, the same bytes
    want = expected_events(table, mapped[3])
    want["t"][2999:3001] = table[2998, 2] - mapped[3] / 1e9
    assert mapped[0].tobytes() == want.tobytes()


def test_what_the_map_must_not_take_goes_through_h5py(tmp_path, monkeypatch):
    table = event_table(300)
    with h5py.File(tmp_path / "x_data.hdf5", "w") as f:  # allocated when first written: never
        f.create_dataset("davis/left/events", shape=(300, 4), dtype="f8")
    (tmp_path / "camchain-imucam-test.yaml").write_text(CAMCHAIN)
    assert not took_the_map(tmp_path / "x_data.hdf5", monkeypatch)
    events = read(tmp_path / "x_data.hdf5", tmp_path / "a", monkeypatch, True)[0]
    assert events.tobytes() == expected_events(np.zeros((300, 4))).tobytes()  # h5py's fill value

    external = tmp_path / "ext"
    external.mkdir()
    table.tofile(external / "rows.bin")
    (external / "camchain-imucam-test.yaml").write_text(CAMCHAIN)
    with h5py.File(external / "x_data.hdf5", "w") as f:  # the rows in another file
        f.create_dataset(
            "davis/left/events",
            shape=table.shape,
            dtype="<f8",
            external=[(str(external / "rows.bin"), 0, table.nbytes)],
        )
    assert not took_the_map(external / "x_data.hdf5", monkeypatch)
    events, _, _, origin_ns = read(external / "x_data.hdf5", tmp_path / "b", monkeypatch, True)
    assert events.tobytes() == expected_events(table, origin_ns).tobytes()


def test_a_file_cut_inside_the_events_after_opening_is_named_not_mapped(tmp_path, monkeypatch):
    """A map of bytes past the file's end would kill the process (SIGBUS) when read. HDF5 checks
    a file's size when it opens it; a file cut inside its rows after that is left to h5py,
    which reads zeros past the end: the first row there is named."""
    path = write_events(tmp_path / "x_data.hdf5", event_table(20_000))
    monkeypatch.setenv("EAS_VO_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(mvsec, "MAP_EVENTS", True)
    ds = MvsecDataset(path)
    offset = ds._events_dset.id.get_offset()
    assert ds._map_events(ds._events_dset) is not None
    os.truncate(path, offset + 10_000 * 32)
    assert ds._map_events(ds._events_dset) is None
    with pytest.raises(DataError) as err:
        ds.events()
    assert str(err.value).startswith(f"{path}:davis/left/events:10000: timestamp goes backwards"), str(err.value)


#: What is written into a row, as in test_mvsec.py's DAMAGE, plus steps back to clamp.
DAMAGE = {
    "time back": lambda r, prev: {2: prev[2] - 0.5},
    "small step back": lambda r, prev: {2: prev[2] - 5e-7},
    "x off the sensor": lambda r, prev: {0: 346.0},
    "x not whole": lambda r, prev: {0: 3.5},
    "polarity 2": lambda r, prev: {3: 2.0},
    "time NaN": lambda r, prev: {2: np.nan},
    "time -0.0 after 0.0": lambda r, prev: {2: -0.0},
}


@hostile_settings(60)
@given(
    damage=st.lists(
        st.tuples(st.integers(1, 2499), st.sampled_from(sorted(DAMAGE))), max_size=5, unique_by=lambda r: r[0]
    ),
    near_seams=st.booleans(),
    block=st.sampled_from([100, 256, 1000]),
    lenient=st.booleans(),
    big=st.booleans(),
)
def test_damaged_rows_read_alike_mapped_and_through_h5py(
    tmp_path_factory, monkeypatch, damage, near_seams, block, lenient, big
):
    """Errors name the same row with the same words; lenient reads drop and count the same rows
    and write the same cache, for damage anywhere and at the seams of the map's blocks."""
    monkeypatch.setattr(mvsec, "MAP_BLOCK_ROWS", block)
    monkeypatch.setattr(mvsec, "BLOCK_ROWS", 700)
    table = event_table(2500, seed=len(damage))
    if any(kind == "time -0.0 after 0.0" for _, kind in damage):
        table[:, 2] -= table[0, 2] + 1e-3  # times from about -1 ms to 0.05 s: 0.0 and -0.0 among them
    for row, kind in damage:
        if near_seams:
            row = min(2499, max(1, row // block * block + (row % 3) - 1))
        if kind == "time -0.0 after 0.0":
            table[row - 1, 2] = 0.0
        for column, value in DAMAGE[kind](table[row], table[row - 1]).items():
            table[row, column] = value
    folder = tmp_path_factory.mktemp("rows")
    path = write_events(folder / "x_data.hdf5", table, dtype=">f8" if big else "<f8")
    mapped = read(path, folder / "a", monkeypatch, True, lenient)
    through_h5py = read(path, folder / "b", monkeypatch, False, lenient)
    if isinstance(through_h5py, str):
        assert mapped == through_h5py
        return
    assert mapped[0].tobytes() == through_h5py[0].tobytes()
    assert mapped[1] == through_h5py[1]  # the same counts, first rows and order
    assert mapped[2] == through_h5py[2]  # the same cache (and warnings beside it), byte for byte
