"""MVSEC HDF5 recordings: a simulated sequence written in MVSEC's layout with plain h5py (this
file's own writer) reads back equal to its ECD folder and runs to the same trajectory; hostile
files are one-line errors naming the file, the HDF5 dataset and the row, or read exactly."""

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from eas_vo.cli.main import main
from eas_vo.datasets import mvsec
from eas_vo.datasets.mvsec import MvsecConfig, MvsecDataset
from eas_vo.errors import DataError, EasVoError
from eas_vo.registry import open_dataset, resolve_dataset
from helpers import hostile_settings, write_mvsec

#: An equidistant camchain as MVSEC publishes them (values of its indoor_flying cam0, 346x260).
CAMCHAIN = """\
cam0:
  camera_model: pinhole
  distortion_coeffs: [-0.048, 0.0016, -0.0055, 0.0018]
  distortion_model: equidistant
  intrinsics: [226.38, 226.15, 173.65, 133.73]
  resolution: [346, 260]
  rostopic: /davis/left/image_raw
cam1:
  camera_model: pinhole
  distortion_coeffs: [-0.047, 0.0011, -0.0041, 0.0010]
  distortion_model: equidistant
  intrinsics: [226.01, 225.76, 174.52, 124.95]
  resolution: [346, 260]
  rostopic: /davis/right/image_raw
"""


@pytest.fixture(scope="module")
def ecd_folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "one_second"
    assert main(["simulate", "--out", str(out), "--duration", "1"]) == 0
    return out


@pytest.fixture(scope="module")
def ecd(ecd_folder):
    return open_dataset(str(ecd_folder))


@pytest.fixture(scope="module")
def h5_path(ecd, tmp_path_factory) -> Path:
    return write_mvsec(tmp_path_factory.mktemp("mvsec"), ecd)


def opened(path: Path, ecd_folder: Path, **options) -> MvsecDataset:
    return MvsecDataset(path, MvsecConfig(calibration=str(ecd_folder / "calib.txt"), **options))


def assert_same_recording(a, b) -> None:
    assert a.camera.width == b.camera.width and a.camera.height == b.camera.height
    np.testing.assert_array_equal(a.camera.K, b.camera.K)
    np.testing.assert_array_equal(a.camera.dist, b.camera.dist)
    assert np.asarray(a.events()).tobytes() == np.asarray(b.events()).tobytes()
    np.testing.assert_array_equal(a.frame_times(), b.frame_times())
    for k in range(len(a.frame_times())):
        np.testing.assert_array_equal(a.load_frame(k), b.load_frame(k))
    for name in ("t", "acc", "gyro"):
        np.testing.assert_array_equal(getattr(a.imu, name), getattr(b.imu, name))
    np.testing.assert_array_equal(a.ground_truth.t, b.ground_truth.t)
    np.testing.assert_allclose(a.ground_truth.p_w_c, b.ground_truth.p_w_c, rtol=0, atol=1e-12)
    # q and -q are one rotation; the ECD text keeps its 9-decimal quaternions as written (unit to
    # 1e-9), the MVSEC matrix gives unit ones
    qa, qb = a.ground_truth.q_w_c, b.ground_truth.q_w_c
    np.testing.assert_allclose(qa * np.sign((qa * qb).sum(axis=1))[:, None], qb, rtol=0, atol=1e-9)


def test_reads_what_the_ecd_folder_holds(h5_path, ecd, ecd_folder):
    ds = opened(h5_path, ecd_folder)
    assert len(ds.events()) > 100_000 and len(ds.frame_times()) > 10
    assert_same_recording(ds, ecd)
    again = opened(h5_path, ecd_folder)  # from the cache now
    assert isinstance(again.events(), np.memmap)
    assert np.asarray(again.events()).tobytes() == np.asarray(ecd.events()).tobytes()


@pytest.mark.parametrize("config", ["paper", "best"])
def test_paper_and_best_runs_give_the_same_trajectory_from_both(h5_path, ecd_folder, tmp_path, config):
    runs = {}
    for name, spec in (("ecd", str(ecd_folder)), ("mvsec", str(h5_path))):
        out = tmp_path / name
        extra = ["--set", f"dataset.calibration={ecd_folder / 'calib.txt'}"] if name == "mvsec" else []
        assert main(["run", "--dataset", spec, "--config", config, "--out", str(out), "--quiet", *extra]) == 0
        runs[name] = np.loadtxt(out / "trajectory.tum")
    assert len(runs["ecd"]) > 10
    np.testing.assert_allclose(runs["mvsec"], runs["ecd"], rtol=0, atol=1e-6)


def test_big_endian_datasets_read_alike(tmp_path):
    camchain(tmp_path)
    table = event_table(500)
    native = MvsecDataset(write_file(tmp_path / "n_data.hdf5", **{**GOOD, "davis/left/events": table}))
    swapped = {
        name: np.asarray(value).astype(np.asarray(value).dtype.newbyteorder(">")) for name, value in GOOD.items()
    }
    big = MvsecDataset(write_file(tmp_path / "b_data.hdf5", **{**swapped, "davis/left/events": table.astype(">f8")}))
    assert (
        big.events().tobytes() == native.events().tobytes() == expected_events(table, native.clock_origin_ns).tobytes()
    )
    np.testing.assert_array_equal(big.imu.t, native.imu.t)


def test_compressed_events_read_through_hdf5plugin(ecd, ecd_folder, tmp_path):
    import hdf5plugin

    path = write_mvsec(tmp_path, ecd, **hdf5plugin.Blosc(cname="zstd"), chunks=(4096, 4))
    ds = opened(path, ecd_folder)
    assert np.asarray(ds.events()).tobytes() == np.asarray(ecd.events()).tobytes()


def test_without_hdf5plugin_a_file_that_needs_its_filter_names_it_in_one_line(ecd, ecd_folder, tmp_path):
    """hdf5plugin is an extra: where it is not installed (hidden from a child process here), a
    blosc-compressed events dataset is one line naming the filter and how to add it."""
    import hdf5plugin

    path = write_mvsec(tmp_path, ecd, **hdf5plugin.Blosc(cname="zstd"), chunks=(4096, 4))
    hidden = "import sys; sys.modules['hdf5plugin'] = None; from eas_vo.cli.main import main; sys.exit(main())"
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            hidden,
            "info",
            "--dataset",
            str(path),
            "--set",
            f"dataset.calibration={ecd_folder / 'calib.txt'}",
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert "davis/left/events: is compressed with HDF5 filter 32001 (blosc" in done.stderr
    assert "pip install hdf5plugin" in done.stderr


def test_side_selects_the_right_davis_and_its_kalibr_camera(ecd, tmp_path):
    path = write_mvsec(tmp_path, ecd, side="right")
    (tmp_path / "camchain-imucam-sim.yaml").write_text(
        CAMCHAIN.replace("[346, 260]", f"[{ecd.camera.width}, {ecd.camera.height}]")
    )
    with pytest.raises(DataError, match=r"seq_data.hdf5: has no group davis/left"):
        MvsecDataset(path)
    ds = MvsecDataset(path, MvsecConfig(side="right"))  # the camchain beside the file, cam1
    assert ds.camera.model == "equidistant"
    np.testing.assert_array_equal(ds.camera.dist, [-0.047, 0.0011, -0.0041, 0.0010])
    np.testing.assert_array_equal(ds.camera.K[0], [226.01, 0, 174.52])
    assert ds.ground_truth is not None and len(ds.events()) == len(ecd.events())


def test_without_a_calibration_the_error_says_how_to_give_one(h5_path, ecd):
    """The file opens (info describes it); a run is refused in one line naming the key."""
    ds = MvsecDataset(h5_path)
    assert ds.camera is None and ds.sensor_size == (ecd.camera.width, ecd.camera.height) and len(ds.events()) > 0
    with pytest.raises(EasVoError, match=r"seq_data.hdf5: the intrinsics are unknown.*--set dataset.calibration=FILE"):
        open_dataset(str(h5_path))


def test_can_open_looks_at_suffix_signature_and_davis_group(h5_path, tmp_path):
    assert resolve_dataset(str(h5_path))[0] is MvsecDataset
    text = tmp_path / "renamed_data.hdf5"
    text.write_text("1.0 2 3 1\n" * 100)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["events"] = np.zeros((3, 4))
    assert not MvsecDataset.can_open(str(text)) and not MvsecDataset.can_open(str(other))
    assert not MvsecDataset.can_open(str(tmp_path / "absent.hdf5"))
    assert not MvsecDataset.can_open(str(h5_path.with_suffix(".bag")))
    with pytest.raises(DataError, match=r"renamed_data.hdf5: not a readable HDF5 file \(.*signature"):
        MvsecDataset(text)


# ----------------------------------------------------------------------------- hostile files


def camchain(folder: Path) -> Path:
    path = folder / "camchain-imucam-test.yaml"
    path.write_text(CAMCHAIN)
    return path


def event_table(n: int, seed: int = 0) -> np.ndarray:
    """n MVSEC event rows on a 346x260 sensor, times increasing from an MVSEC-like epoch [s]."""
    rng = np.random.default_rng(seed)
    t = 1_504_645_177.0 + np.cumsum(rng.uniform(0, 2e-5, n))
    return np.column_stack([rng.integers(0, 346, n), rng.integers(0, 260, n), t, rng.choice([-1.0, 1.0], n)])


def write_file(path: Path, **datasets) -> Path:
    """An HDF5 file holding `datasets` ({'davis/left/events': array, ...})."""
    with h5py.File(path, "w") as f:
        for name, value in datasets.items():
            f[name] = value
    return path


def expected_events(rows: np.ndarray, origin_ns: int = 0) -> np.ndarray:
    """The records of MVSEC rows, their times after the reader's clock origin [ns]."""
    from eas_vo.types import EVENT_DTYPE

    ev = np.empty(len(rows), EVENT_DTYPE)
    ev["x"], ev["y"], ev["t"], ev["p"] = rows[:, 0], rows[:, 1], rows[:, 2] - origin_ns / 1e9, rows[:, 3] > 0
    return ev


DAMAGE = {  # what is written into the row, and what the strict error says
    "time back": (lambda r: {2: r[2] - 0.5}, "timestamp goes backwards"),
    "x off the sensor": (lambda r: {0: 346.0}, "pixel outside the 346x260 sensor: (346, "),
    "y negative": (lambda r: {1: -1.0}, "pixel outside the 346x260 sensor"),
    "x not whole": (lambda r: {0: 3.5}, "pixel coordinates and polarity must be integers: x y p = 3.5 "),
    "polarity half": (lambda r: {3: 0.5}, "pixel coordinates and polarity must be integers"),
    "time NaN": (lambda r: {2: np.nan}, "timestamp is not finite"),
    "x NaN": (lambda r: {0: np.nan}, "pixel coordinates and polarity must be integers: x y p = nan"),
    "x huge": (lambda r: {0: 1e300}, "pixel coordinates and polarity must be integers"),
}


@hostile_settings(60)
# (from row 1: row 0 going back is no problem, nothing precedes it)
@given(
    rows=st.lists(
        st.tuples(st.integers(1, 2999), st.sampled_from(sorted(DAMAGE))),
        min_size=1,
        max_size=4,
        unique_by=lambda r: r[0],
    ),
    block=st.sampled_from([64, 1000, 1 << 20]),
)
def test_damaged_event_rows_are_named_or_dropped_exactly(tmp_path_factory, monkeypatch, rows, block):
    monkeypatch.setattr(mvsec, "BLOCK_ROWS", block)
    table = event_table(3000)
    for row, kind in rows:
        for column, value in DAMAGE[kind][0](table[row]).items():
            table[row, column] = value
    folder = tmp_path_factory.mktemp("rows")
    camchain(folder)
    path = write_file(folder / "x_data.hdf5", **{"davis/left/events": table})
    first_row, first_kind = min(rows)
    with pytest.raises(DataError) as err:
        MvsecDataset(path).events()
    message = str(err.value)
    assert message.startswith(f"{path}:davis/left/events:{first_row}: {DAMAGE[first_kind][1]}"), message
    assert "\n" not in message
    lenient = MvsecDataset(path, MvsecConfig(lenient=True))
    keep = np.setdiff1d(np.arange(3000), [r for r, _ in rows])
    assert lenient.events().tobytes() == expected_events(table[keep], lenient.clock_origin_ns).tobytes()
    assert sum(int(line.split(": ")[1].split()[0]) for line in lenient.data_warnings()) == len(rows)


def test_a_small_step_back_is_clamped_not_dropped(tmp_path):
    table = event_table(100)
    table[50, 2] = table[49, 2] - 1e-7
    camchain(tmp_path)
    ds = MvsecDataset(write_file(tmp_path / "x_data.hdf5", **{"davis/left/events": table}))
    events = ds.events()
    assert ds.clock_origin_ns == 1_504_645_177 * 10**9  # MVSEC's Unix clock, read after its first second
    assert len(events) == 100 and events["t"][50] == table[49, 2] - 1_504_645_177


GOOD = {
    "davis/left/events": event_table(50),
    "davis/left/image_raw": np.zeros((3, 260, 346), np.uint8),
    "davis/left/image_raw_ts": [1.0, 2.0, 3.0],
    "davis/left/imu": np.zeros((4, 6)),
    "davis/left/imu_ts": [1.0, 1.1, 1.2, 1.3],
}


@pytest.mark.parametrize(
    "name, value, says",
    [
        ("davis/left/events", np.zeros((5, 3)), "davis/left/events: has shape 5 x 3, expected 2 dimensions, 4 columns"),
        ("davis/left/events", event_table(5).astype(np.float32), "davis/left/events: holds float32, expected float64"),
        ("davis/left/events", np.zeros(4), "davis/left/events: has shape 4, expected 2 dimensions, 4 columns"),
        ("davis/left/image_raw", np.zeros((3, 260, 346)), "davis/left/image_raw: holds float64, expected uint8"),
        (
            "davis/left/image_raw",
            np.zeros((3, 260, 346, 3), np.uint8),
            "davis/left/image_raw: has shape 3 x 260 x 346 x 3",
        ),
        ("davis/left/image_raw_ts", [1.0, 2.0], "davis/left/image_raw_ts: holds 2 times for 3 frames"),
        ("davis/left/image_raw_ts", [1.0, 3.0, 2.0], "davis/left/image_raw_ts:2: timestamp 2.000000000 goes back"),
        ("davis/left/image_raw_ts", [1.0, np.nan, 2.0], "davis/left/image_raw_ts:1: timestamp nan is not finite"),
        ("davis/left/imu", np.zeros((4, 7)), "davis/left/imu: has shape 4 x 7, expected 2 dimensions, 6 columns"),
        (
            "davis/left/imu",
            np.array([[0.0] * 6] * 3 + [[np.inf] + [0.0] * 5]),
            "davis/left/imu:3: holds a value that is not finite",
        ),
        (
            "davis/left/imu_ts",
            [1.0, 1.1, 1.1, 1.3],
            "davis/left/imu_ts:2: timestamp 1.100000000 repeats the previous row's",
        ),
        ("davis/left/imu_ts", [1.0, 1.1, 1.05, 1.3], "davis/left/imu_ts:2: timestamp 1.050000000 does not increase"),
        ("davis/left/imu_ts", [1.0, 1.1, 1.2], "davis/left/imu_ts: holds 3 times for 4 rows of davis/left/imu"),
        ("davis/left/imu_ts", None, "davis/left/imu_ts: missing: the times of davis/left/imu"),
        ("davis/left/imu", np.zeros((1, 6)), "davis/left/imu_ts: holds 4 times for 1 rows of davis/left/imu"),
        (
            {"davis/left/imu": np.zeros((1, 6)), "davis/left/imu_ts": [1.0]},
            None,
            "davis/left/imu: holds 1 row(s); at least 2 are needed",
        ),
        ("davis/left/events", h5py.Empty("f8"), "davis/left/events: has shape null, expected 2 dimensions"),
        ("davis/left/events", 3.0, "davis/left/events: has shape scalar, expected 2 dimensions"),
        ("davis/left/image_raw", np.zeros((3, 0, 346), np.uint8), "frames are 346x0, not an event camera's"),
    ],
)
def test_datasets_of_the_wrong_shape_dtype_or_times(tmp_path, name, value, says):
    camchain(tmp_path)
    content = dict(GOOD)
    for key, new in (name if isinstance(name, dict) else {name: value}).items():
        if new is None:
            del content[key]
        else:
            content[key] = new
    path = write_file(tmp_path / "x_data.hdf5", **content)
    with pytest.raises(DataError) as err:
        MvsecDataset(path).events()
    assert str(err.value).startswith(f"{path}:") and says in str(err.value) and "\n" not in str(err.value), str(
        err.value
    )


def test_lenient_drops_frames_going_back(tmp_path):
    camchain(tmp_path)
    frames = np.arange(3, dtype=np.uint8)[:, None, None] * np.ones((3, 260, 346), np.uint8)
    path = write_file(
        tmp_path / "x_data.hdf5", **{**GOOD, "davis/left/image_raw": frames, "davis/left/image_raw_ts": [1.0, 3.0, 2.0]}
    )
    ds = MvsecDataset(path, MvsecConfig(lenient=True))
    np.testing.assert_array_equal(ds.frame_times(), [1.0, 3.0])
    assert ds.load_frame(1)[0, 0] == 1
    assert ds.data_warnings() == [f"{path}:davis/left/image_raw_ts: 1 dropped: timestamp going back (first at row 2)"]


def test_empty_streams(tmp_path):
    camchain(tmp_path)
    frames_only = write_file(tmp_path / "f_data.hdf5", **{**GOOD, "davis/left/events": np.zeros((0, 4))})
    ds = MvsecDataset(frames_only)
    assert len(ds.events()) == 0 and len(ds.frame_times()) == 3
    events_only = write_file(
        tmp_path / "e_data.hdf5",
        **{"davis/left/events": event_table(1000), "davis/left/image_raw": np.zeros((0, 260, 346), np.uint8)},
    )
    ds = MvsecDataset(events_only, MvsecConfig(sample_every_events=100, width=640, height=480))  # size: image_raw's
    assert (ds.camera.width, ds.camera.height) == (346, 260)
    assert ds.load_frame(0) is None and len(ds.frame_times()) == 10 and "event-only" in ds.no_frames_reason
    nothing = write_file(tmp_path / "n_data.hdf5", **{"davis/left/events": np.zeros((0, 4))})
    ds = MvsecDataset(nothing)
    assert len(ds.events()) == 0 and len(ds.frame_times()) == 0
    with pytest.raises(DataError, match=r"g_data.hdf5: davis/left holds neither events nor image_raw"):
        MvsecDataset(write_file(tmp_path / "g_data.hdf5", **{"davis/left/imu": np.zeros((4, 6))}))


def pose_file(path: Path, T: np.ndarray, t=None) -> Path:
    return write_file(
        path, **{"davis/left/pose": T, "davis/left/pose_ts": np.arange(len(T)) * 0.01 if t is None else t}
    )


@pytest.mark.parametrize(
    "damage, says",
    [
        (lambda T: T.__setitem__((2, 0, 0), 2.0), "x_gt.hdf5:davis/left/pose:2: is not a rigid transform"),
        (lambda T: T.__setitem__((1, 3, 0), 0.5), "x_gt.hdf5:davis/left/pose:1: is not a rigid transform"),
        (
            lambda T: T.__setitem__((3, slice(0, 3), slice(0, 3)), -np.eye(3)),
            "x_gt.hdf5:davis/left/pose:3: is not a rigid",
        ),
        (lambda T: T.__setitem__((0, 0, 3), np.nan), "x_gt.hdf5:davis/left/pose:0: holds a value that is not finite"),
    ],
)
def test_ground_truth_poses_must_be_rigid(tmp_path, damage, says):
    camchain(tmp_path)
    data = write_file(tmp_path / "x_data.hdf5", **GOOD)
    T = np.tile(np.eye(4), (5, 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(np.outer(np.arange(5), [0.1, 0.2, 0.3])).as_matrix()
    pose_file(tmp_path / "x_gt.hdf5", T)
    gt = MvsecDataset(data).ground_truth
    np.testing.assert_allclose(Rotation.from_quat(gt.q_w_c).as_matrix(), T[:, :3, :3], atol=1e-12)
    damage(T)
    pose_file(tmp_path / "x_gt.hdf5", T)
    with pytest.raises(DataError) as err:
        MvsecDataset(data)
    assert says in str(err.value) and "\n" not in str(err.value), str(err.value)


@hostile_settings(30)
@given(cut=st.floats(0.0, 1.0), flip=st.integers(0, 10**9))
def test_truncated_or_damaged_file_is_named_or_read_exactly(tmp_path_factory, cut, flip):
    folder = tmp_path_factory.mktemp("t")
    camchain(folder)
    table = event_table(20_000)
    whole = write_file(folder / "whole.hdf5", **{**GOOD, "davis/left/events": table}).read_bytes()
    data = bytearray(whole[: int(len(whole) * cut)])
    if data and flip % 2:
        data[flip % len(data)] ^= 0xFF
    path = folder / "x_data.hdf5"
    path.write_bytes(bytes(data))
    try:
        ds = MvsecDataset(path)
        events, frames = ds.events(), [ds.load_frame(k) for k in range(len(ds.frame_times()))]
    except DataError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc), str(exc)
        return
    # accepted: only with every byte there, or one flipped where it changes no event, frame or time
    assert len(events) <= len(table) and len(frames) <= 3
    if not flip % 2:
        assert events.tobytes() == expected_events(table, ds.clock_origin_ns).tobytes()


@pytest.mark.parametrize("bad_row", [None, 150, 250, 450])
def test_a_damaged_chunk_is_named_by_its_first_row_after_earlier_bad_rows(tmp_path, monkeypatch, bad_row):
    monkeypatch.setattr(mvsec, "BLOCK_ROWS", 100)
    camchain(tmp_path)
    table = event_table(1000)
    if bad_row is not None:
        table[bad_row, 0] = 999.0  # off the sensor
    path = tmp_path / "x_data.hdf5"
    with h5py.File(path, "w") as f:
        f.create_dataset("davis/left/events", data=table, chunks=(100, 4), compression="gzip")
        info = f["davis/left/events"].id.get_chunk_info(3)  # rows 300-399
    data = bytearray(path.read_bytes())
    data[info.byte_offset : info.byte_offset + info.size] = bytes(info.size)
    path.write_bytes(bytes(data))
    with pytest.raises(DataError) as err:
        MvsecDataset(path).events()
    if bad_row in (150, 250):  # 250: in the block packed while the damaged one is read
        assert str(err.value).startswith(f"{path}:davis/left/events:{bad_row}: pixel outside the 346x260 sensor")
    else:
        assert str(err.value).startswith(f"{path}:davis/left/events:300: unreadable from this row on (")
    assert "\n" not in str(err.value)


def test_a_simulated_fisheye_gives_the_same_ape_through_mvsec_as_through_its_ecd_folder(tmp_path):
    """The DAVIS346 preset (MVSEC's own equidistant lens) simulated for 1 s: its ECD folder
    (camchain.yaml) and the same sequence in MVSEC's layout with that camchain beside it give
    the same camera, the same trajectory and the same APE."""
    folder = tmp_path / "fisheye"
    assert main(["simulate", "--out", str(folder), "--duration", "1", "--set", "dataset.sensor=davis346"]) == 0
    seq = open_dataset(str(folder))
    assert seq.camera.model == "equidistant" and (seq.camera.width, seq.camera.height) == (346, 260)
    h5 = write_mvsec(tmp_path / "mvsec", seq)
    (tmp_path / "mvsec" / "seq_camchain.yaml").write_bytes((folder / "camchain.yaml").read_bytes())
    runs = {}
    for name, spec in (("ecd", folder), ("mvsec", h5)):
        out = tmp_path / f"run_{name}"
        assert main(["run", "--dataset", str(spec), "--config", "paper", "--out", str(out), "--quiet"]) == 0
        runs[name] = np.loadtxt(out / "trajectory.tum"), json.loads((out / "metrics.json").read_text())["ape_mean_rad"]
    np.testing.assert_allclose(runs["mvsec"][0], runs["ecd"][0], rtol=0, atol=1e-6)
    assert runs["mvsec"][1] == pytest.approx(runs["ecd"][1], abs=1e-9)
