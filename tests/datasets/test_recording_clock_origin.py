"""No result depends on where a recording's clock starts: the same recording with its times at
0 s and at Unix time (1.7e9 s, where float64 seconds keep only about 0.24 us) gives the same
`info`, the same trajectory, and files whose times are the recording's own."""

from __future__ import annotations

import numpy as np
import pytest

from eas_vo import config, pipeline
from eas_vo.datasets.ecd import EcdFolderDataset, write_ecd_folder
from eas_vo.datasets.rosbag import write_bag
from eas_vo.datasets.rosbag2 import write_bag2
from eas_vo.io.tables import clock_time
from eas_vo.plugins import Dataset
from eas_vo.sequence.info import describe
from helpers import InMemoryDataset, write_aedat4, write_mvsec

#: 2023-11-14 22:13:20 UTC [ns].
UNIX_NS = 1_700_000_000 * 10**9
#: Times are put on a grid of 2**-22 s: float64 holds them exactly both near 0 and at 1.7e9 s
#: (its spacing there), so the shifted file holds the same instants and not rounded ones.
GRID_S = 2.0**-22


def on_grid(t: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t) / GRID_S) * GRID_S


def on_clock(base: Dataset, origin_ns: int, absolute: bool = False) -> InMemoryDataset:
    """`base` with its times on the grid, after the clock origin `origin_ns`; with `absolute`,
    the same instants as float64 seconds of that clock itself (origin 0), as a file format
    without an origin of its own (MVSEC) holds them."""
    shift = origin_ns / 1e9 if absolute else 0.0
    events = np.array(base.events())
    events["t"] = on_grid(events["t"]) + shift
    imu, gt = base.imu, base.ground_truth
    times = on_grid(base.frame_times()) + shift
    return InMemoryDataset(
        base.camera,
        times,
        [base.load_frame(k) for k in range(len(times))],
        events,
        type(imu)(on_grid(imu.t) + shift, imu.acc, imu.gyro),
        type(gt)(on_grid(gt.t) + shift, gt.p_w_c, gt.q_w_c),
        0 if absolute else origin_ns,
    )


def ecd_folder(ds, folder):
    frames = (ds.load_frame(k) for k in range(len(ds.frame_times())))
    write_ecd_folder(
        folder / "seq", ds.camera, ds.frame_times(), frames, ds.events(), ds.ground_truth, ds.imu, ds.clock_origin_ns
    )
    return folder / "seq"


def aedat4_file(ds, folder):
    """As DV records: integer microseconds of the Unix clock, frames stamped at the start of a
    2 ms exposure centred on the frame's time, IMU in g and deg/s; poses in a TUM file beside."""
    origin_us = ds.clock_origin_ns // 1000
    us = lambda t: np.round(np.asarray(t) * 1e6).astype(np.int64) + origin_us  # noqa: E731
    events = ds.events()
    frames = [(int(us(t)) - 1000, 2000, ds.load_frame(k)) for k, t in enumerate(ds.frame_times())]
    imu = np.column_stack([us(ds.imu.t), ds.imu.acc / 9.80665, np.degrees(ds.imu.gyro)])
    write_aedat4(
        folder / "rec.aedat4",
        size=(ds.camera.width, ds.camera.height),
        frames=frames,
        imu=imu.tolist(),
        events=(us(events["t"]), events["x"], events["y"], events["p"]),
    )
    gt = ds.ground_truth
    (folder / "gt.tum").write_text(
        "".join(
            f"{clock_time(t, ds.clock_origin_ns)} {' '.join(repr(float(v)) for v in (*p, *q))}\n"
            for t, p, q in zip(gt.t, gt.p_w_c, gt.q_w_c)
        )
    )
    return folder / "rec.aedat4"


WRITERS = {
    "aedat4": aedat4_file,
    "ecd": ecd_folder,
    "rosbag": lambda ds, folder: (write_bag(ds, folder / "rec.bag"), folder / "rec.bag")[1],
    "rosbag2-sqlite3-dvs": lambda ds, folder: (write_bag2(ds, folder / "bag", "sqlite3"), folder / "bag")[1],
    "rosbag2-mcap-mono": lambda ds, folder: (write_bag2(ds, folder / "bag", "mcap", encoding="mono"), folder / "bag")[
        1
    ],
    "mvsec": lambda ds, folder: write_mvsec(folder, ds),
}


@pytest.fixture(scope="module")
def base(short_sequence):
    return EcdFolderDataset(short_sequence)


def _written(base, fmt: str, origin_ns: int, folder):
    absolute = fmt == "mvsec"
    folder.mkdir()
    path = WRITERS[fmt](on_clock(base, origin_ns, absolute), folder)
    extra = [f"dataset.calibration={base.label}/calib.txt"] if fmt in ("mvsec", "aedat4") else []
    extra += [f"dataset.ground_truth={folder / 'gt.tum'}"] if fmt == "aedat4" else []
    return str(path), extra


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_a_unix_clock_gives_the_same_info_and_trajectory(base, fmt, tmp_path):
    runs, infos = {}, {}
    for name, origin_ns in (("zero", 0), ("unix", UNIX_NS)):
        spec, extra = _written(base, fmt, origin_ns, tmp_path / name)
        resolved = config.resolve("paper", {"dataset": spec, "frontend": "eas"}, extra)
        info = describe(resolved)
        assert info.clock_origin_ns == origin_ns
        infos[name] = [line for line in info.lines()[1:] if not line.lstrip().startswith(("clock", "to run", "file"))]
        runs[name] = pipeline.run(resolved, tmp_path / f"{name}_run")
    assert infos["unix"] == infos["zero"]
    zero, unix = runs["zero"], runs["unix"]
    assert len(zero.t) == len(unix.t) > 10
    np.testing.assert_allclose(unix.t, zero.t, rtol=0, atol=1e-9)  # (text: the 9 decimals' own rounding)
    np.testing.assert_allclose(unix.R_w_c, zero.R_w_c, rtol=0, atol=1e-6)
    assert unix.metrics["ape_mean_rad"] == pytest.approx(zero.metrics["ape_mean_rad"], abs=1e-6)
    # The files hold the recording's own times: the Unix run's are the other's + 1.7e9 s, to the digit.
    zero_t, unix_t = (
        [line.split()[0] for line in (tmp_path / f"{name}_run" / "trajectory.tum").read_text().splitlines()]
        for name in ("zero", "unix")
    )
    for a, b in zip(zero_t, unix_t):
        whole, frac = a.split(".")
        assert b == f"{int(whole) + 1_700_000_000}.{frac}"
