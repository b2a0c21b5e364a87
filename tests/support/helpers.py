"""Helpers the tests share (imported as `helpers`: `tests/support` is on pytest's pythonpath):
where the real data lives, skipping without it, and manifold-aware asserts."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import cv2
import numpy as np
import pytest

from eas_vo.camera import CameraModel
from eas_vo.plugins import Dataset
from eas_vo.types import EVENT_DTYPE, ImuSeries, PoseSeries

SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
SHAPES_ROTATION = SHARED_DATA / "ecd" / "shapes_rotation_0-30s"
EVENT_WINDOWS = SHARED_DATA / "ecd" / "event_windows"
#: Recordings written by real cameras and tools (the ROS event_camera_py package's test bags).
EVENT_CAMERA_PY = SHARED_DATA / "real_files" / "event_camera_py"
REPOSITORY = Path(__file__).resolve().parents[2]


def require(path: Path) -> Path:
    """Skip the test, saying why, when a real-data folder is absent."""
    if not path.exists():
        pytest.skip(f"real data not available: {path} is absent (it lives in ../shared/data beside the repository)")
    return path


def assert_rotations_close(R_a, R_b, tol_rad: float) -> None:
    """Manifold-aware comparison of rotation stacks: every geodesic angle below tol_rad."""
    from eas_vo.geometry.rotations import geodesic_angle

    angles = np.atleast_1d(geodesic_angle(np.asarray(R_a), np.asarray(R_b)))
    assert angles.max() <= tol_rad, f"largest rotation difference {angles.max():.3g} rad > {tol_rad:.3g} rad"


def code_blocks(text: str, language: str | None = None) -> list[str]:
    """The fenced code blocks of a Markdown text (of one language, if given)."""
    return [
        body
        for lang, body in re.findall(r"^```(\w*)\n(.*?)^```", text, re.S | re.M)
        if language is None or lang == language
    ]


def shell_commands(text: str) -> list[tuple[dict[str, str], list[str]]]:
    """Every command in the text's code blocks as (environment assignments, words): lines
    joined at a trailing backslash; `&&`, `|` and `;` separate commands; comments dropped;
    leading `NAME=value` words taken as the command's environment."""
    commands = []
    for block in code_blocks(text):
        for line in block.replace("\\\n", " ").splitlines():
            try:
                words = shlex.split(line, comments=True)
            except ValueError:
                continue
            command: list[str] = []
            for word in [*words, "&&"]:
                if word not in ("&&", "||", "|", ";"):
                    command.append(word)
                    continue
                env = {}
                while command and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", command[0]):
                    name, _, value = command.pop(0).partition("=")
                    env[name] = value
                if command:
                    commands.append((env, command))
                command = []
    return commands


def random_events(n: int, seed: int = 0):
    """n events (EVENT_DTYPE) sorted by time over [0, 1234.5] s on a 240x180 sensor."""
    rng = np.random.default_rng(seed)
    ev = np.empty(n, EVENT_DTYPE)
    ev["t"] = np.sort(rng.uniform(0, 1234.5, n))
    ev["x"] = rng.integers(0, 240, n)
    ev["y"] = rng.integers(0, 180, n)
    ev["p"] = rng.integers(0, 2, n)
    return ev


def load_event_file(path, lenient=False, warnings=None, width=240, height=180, tolerance_s=1e-6):
    """An events.txt through eas_vo.eventfile.load_event_text (and its cache)."""
    from eas_vo.eventfile import file_identity, load_event_text

    return load_event_text(
        lambda: open(path, "rb"), file_identity(path), str(path), width, height, tolerance_s, lenient, warnings
    )


# ----------------------------------------------------------------------------- hostile input (hypothesis)


def hostile_settings(max_examples: int = 150):
    """Property-test settings: deterministic, no deadline (the readers hit the disk)."""
    from hypothesis import HealthCheck, settings

    return settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


def hostile_number():
    """Number-like text: good numbers, NaN/inf, overflow, hex, empty, words, a non-ASCII digit."""
    from hypothesis import strategies as st

    return st.one_of(
        st.integers(-10, 400).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.floats(0, 100).map(lambda v: f"{v:.9f}"),
        st.sampled_from(["nan", "inf", "-1", "1e309", "0x10", "", "abc", "1.2.3", "٣"]),
    )


def numeric_rows(text: str) -> list[list[float]]:
    """A reference reading of a whitespace table: the non-blank, non-comment lines as floats."""
    return [
        [float(v) for v in line.split()]
        for line in text.splitlines()
        if line.strip() and not line.strip().startswith("#")
    ]


def run_eas_vo(*argv: str, env: dict | None = None):
    """`python -m eas_vo ARGV` in a subprocess, from a neutral folder: `-m` puts the current
    folder on sys.path, and from the repository root the source `eas_vo/` would shadow a
    non-editable installation."""
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as neutral:
        return subprocess.run(
            [sys.executable, "-m", "eas_vo", *argv], capture_output=True, text=True, env=env, cwd=neutral
        )


def closed_port_url() -> str:
    """http://127.0.0.1:PORT/ for a loopback port nothing listens on (a server that is down)."""
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"http://127.0.0.1:{probe.getsockname()[1]}/"


def one_line_failure(argv, capsys, usage: bool = False) -> str:
    """Run the CLI in-process; it must fail with exactly one line on stderr and status 1 (an
    error in the data or the configuration) or, for a `usage` error in the options, 2."""
    from eas_vo.cli.main import main

    try:
        status = main(argv)
    except SystemExit as exit_:  # argparse's usage errors
        status = exit_.code
    err = capsys.readouterr().err
    assert status == (2 if usage else 1) and err.count("\n") == 1 and "Traceback" not in err, (status, err)
    return err


# ----------------------------------------------------------------------------- synthetic views

#: A pinhole camera without distortion for warped-image tests.
K = np.array([[200.0, 0, 120], [0, 200.0, 90], [0, 0, 1]])
CAMERA = CameraModel(240, 180, K)


def textured_image(seed=0, size=(180, 240), shapes=120):
    """Random rectangles and discs: plenty of corners."""
    rng = np.random.default_rng(seed)
    img = np.full(size, 60, np.uint8)
    for _ in range(shapes):
        x, y = rng.integers(0, size[1]), rng.integers(0, size[0])
        r = int(rng.integers(4, 14))
        colour = int(rng.integers(0, 256))
        if rng.random() < 0.5:
            cv2.rectangle(img, (x - r, y - r), (x + r, y + int(r * 0.7)), colour, -1)
        else:
            cv2.circle(img, (x, y), r, colour, -1)
    return cv2.GaussianBlur(img, (3, 3), 0.7)


def warp_by_rotation(img, R_c2_c1):
    """The view of a camera rotated by R_c1_c2 = R_c2_c1^T: x2 ~ K R_c2_c1 K^-1 x1 (infinite depth)."""
    H = K @ R_c2_c1 @ np.linalg.inv(K)
    return cv2.warpPerspective(img, H, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR, borderValue=60)


def large_rotation(rng, angle_deg=(15, 25), roll_deg=(10, 12)) -> np.ndarray:
    """R_c0_c1 of a fast hand-held step: 15-25 degrees in all, of which 10-12 degrees of roll."""
    from scipy.spatial.transform import Rotation

    angle = np.radians(rng.uniform(*angle_deg))
    roll = np.radians(rng.uniform(*roll_deg)) * rng.choice([-1, 1])
    axis = rng.normal(size=2)
    tilt = np.sqrt(angle**2 - roll**2) * axis / np.linalg.norm(axis)
    return Rotation.from_rotvec([tilt[0], tilt[1], roll]).as_matrix()


#: MVSEC's left DAVIS346 (its indoor_flying kalibr camchain): an equidistant fisheye, 118 deg
#: across the diagonal, so the sensor's corners are 60 deg off the axis.
MVSEC_LEFT = CameraModel(
    346,
    260,
    np.array(
        [[226.38018519795807, 0.0, 173.6470807871759], [0.0, 226.15002947047415, 133.73271487507847], [0.0, 0.0, 1.0]]
    ),
    np.array([-0.048031442223833355, 0.011330957517194437, -0.055378166304281135, 0.021500973881459395]),
    "equidistant",
)
#: The Event Camera Dataset's DAVIS240C (shapes_rotation calib.txt): strong barrel distortion.
ECD_DAVIS240 = CameraModel.from_calib(
    [
        199.092366542,
        198.82882047,
        132.192071378,
        110.712660011,
        -0.368436311798,
        0.150947243557,
        -0.000296130534385,
        -0.000759431726241,
        0.0,
    ]
)


def opencv_rotated(camera: CameraModel, R_to_from: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Pixels px (N, 2) of a view in the view rotated from it (ray_to = R_to_from ray_from), by
    OpenCV's own lens functions (cv2.fisheye for the equidistant model)."""
    fisheye = camera.model == "equidistant"
    undistort = cv2.fisheye.undistortPoints if fisheye else cv2.undistortPoints
    normalised = undistort(px.reshape(-1, 1, 2).astype(np.float64), camera.K, camera.dist).reshape(-1, 2)
    rays = np.column_stack([normalised, np.ones(len(px))])
    rvec = cv2.Rodrigues(np.asarray(R_to_from, np.float64))[0]
    if fisheye:
        return cv2.fisheye.projectPoints(rays.reshape(-1, 1, 3), rvec, np.zeros(3), camera.K, camera.dist)[0].reshape(
            -1, 2
        )
    return cv2.projectPoints(rays, rvec, np.zeros(3), camera.K, camera.dist)[0].reshape(-1, 2)


# ----------------------------------------------------------------------------- download site


def publish_sequences(site: Path, sequences: dict[str, Path], registry: Path) -> dict[str, str]:
    """Zip each ECD folder as `site/NAME.zip` (files at the root, as the dataset publishes
    them) and write `registry` (`name md5` lines); returns {name: md5}."""
    import hashlib
    import io
    import zipfile

    md5s = {}
    for name, folder in sequences.items():
        files = sorted(p for p in folder.rglob("*") if p.is_file())
        key = (str(folder), tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in files))
        if key not in _ZIPPED:  # compressing takes seconds; a folder as it was zipped before is not again
            buffer = io.BytesIO()
            with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as z:
                for path in files:
                    z.write(path, path.relative_to(folder).as_posix())
            _ZIPPED[key] = buffer.getvalue()
        (site / f"{name}.zip").write_bytes(_ZIPPED[key])
        md5s[name] = hashlib.md5(_ZIPPED[key]).hexdigest()
    registry.write_text("".join(f"{n} {m}\n" for n, m in md5s.items()))
    return md5s


#: publish_sequences' archives: {(folder, its files' names, sizes and times): the zip's bytes}.
_ZIPPED: dict[tuple, bytes] = {}


def mark_as_eas_vo_output(folder: Path) -> None:
    """Give `folder` the marker eas-vo leaves, listing all its files (as `eas-vo simulate` leaves
    a dataset): only the checks against writing over inputs stand in the way of --overwrite."""
    from eas_vo.io.outputs import OUTPUT_MARKER

    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    (folder / OUTPUT_MARKER).write_text("".join(f"{line}\n" for line in ["written by eas-vo:", *files]))


# ----------------------------------------------------------------------------- a written sequence

#: known_sequence's content: frames every 1/25 s from 0.5 s, events over 0.4-1.0 s, ground
#: truth at 200 Hz from 0.45 s, IMU at 250 Hz from 0.42 s (to 1.016 s, the latest of all).
N_FRAMES, FRAME_T0, FRAME_HZ = 12, 0.5, 25.0
N_EVENTS, N_POSES, N_READINGS = 5000, 100, 150


def known_sequence(folder: Path, width: int = 346, height: int = 260, frames: bool = True) -> Path:
    """An ECD folder of random content with the module's counts and rates; the camera's focal
    length and centre follow the sensor size."""
    from eas_vo.datasets.ecd import write_ecd_folder

    rng = np.random.default_rng(7)
    f = 0.8 * width
    camera = CameraModel(
        width,
        height,
        np.array([[f, 0, width / 2 - 0.3], [0, f * 1.01, height / 2 + 0.7], [0, 0, 1]]),
        np.array([-0.21, 0.047, 1.3e-4, -2.1e-4, 0.0]),
    )
    times = FRAME_T0 + np.arange(N_FRAMES) / FRAME_HZ
    images = [rng.integers(0, 256, (height, width), dtype=np.uint8) for _ in times]
    events = np.zeros(N_EVENTS, EVENT_DTYPE)
    events["t"] = np.sort(rng.uniform(0.4, 1.0, N_EVENTS))
    events["x"], events["y"] = rng.integers(0, width, N_EVENTS), rng.integers(0, height, N_EVENTS)
    events["p"] = rng.integers(0, 2, N_EVENTS)
    q = rng.normal(size=(N_POSES, 4))
    poses = PoseSeries(
        0.45 + np.arange(N_POSES) / 200.0, rng.normal(size=(N_POSES, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)
    )
    imu = ImuSeries(
        0.42 + np.arange(N_READINGS) / 250.0, rng.normal(size=(N_READINGS, 3)), rng.normal(size=(N_READINGS, 3))
    )
    write_ecd_folder(folder, camera, times, images if frames else None, events, poses, imu)
    return folder


#: 2023-11-14 22:13:20 UTC [s]: a Unix-time clock.
UNIX_S = 1_700_000_000
#: The ECD text file of each timed stream (recording.time_sources' names).
ECD_FILES = {"event": "events.txt", "frame": "images.txt", "IMU": "imu.txt", "ground-truth": "groundtruth.txt"}


def retimed(path, factor: int = 1, shift_s: int = 0) -> None:
    """The first column of an ECD text file as (t + shift_s) * factor, written exactly (integers
    of the unit for factor > 1)."""
    lines = []
    for line in path.read_text().splitlines():
        t, rest = line.split(" ", 1)
        whole, _, fraction = t.partition(".")
        ticks = (int(whole) + shift_s) * 10**9 + int(fraction.ljust(9, "0"))  # exact: integer nanoseconds
        new = str(ticks * factor // 10**9) if factor > 1 else f"{ticks // 10**9}.{ticks % 10**9:09d}"
        lines.append(f"{new} {rest}")
    path.write_text("\n".join(lines) + "\n")


def sequence_with(folder, stream: str | None, factor: int, shift_s: int = 0):
    """known_sequence with every file on a clock shifted by shift_s [s], and `stream`'s times
    multiplied by `factor` (its unit)."""
    known_sequence(folder)
    for name, file in ECD_FILES.items():
        retimed(folder / file, factor if name == stream else 1, shift_s)
    return folder


# ----------------------------------------------------------------------------- writers and damage


class InMemoryDataset(Dataset):
    """A recording held in memory (what the formats' writers take): the camera, frame times [s]
    with their uint8 frames, EVENT_DTYPE events, IMU and ground truth (or None), all after the
    clock origin `clock_origin_ns`."""

    def __init__(
        self,
        camera: CameraModel,
        times,
        frames,
        events,
        imu: ImuSeries | None = None,
        ground_truth: PoseSeries | None = None,
        clock_origin_ns: int = 0,
    ):
        self.camera, self._times, self._frames, self._events = camera, np.asarray(times), list(frames), events
        self.imu, self.ground_truth, self.clock_origin_ns = imu, ground_truth, clock_origin_ns

    def frame_times(self):
        return self._times

    def load_frame(self, k):
        return self._frames[k]

    def events(self):
        return self._events


def mvsec_rows(events: np.ndarray) -> np.ndarray:
    """EVENT_DTYPE -> MVSEC's (N, 4) float64 rows x y t p, p in {-1, 1}."""
    return np.column_stack([events["x"], events["y"], events["t"], np.where(events["p"] > 0, 1.0, -1.0)])


def write_mvsec(folder: Path, seq, name: str = "seq", side: str | tuple[str, ...] = "left", **events_options) -> Path:
    """Write `seq` (a Dataset) as MVSEC's NAME_data.hdf5 and NAME_gt.hdf5 with plain h5py, as the
    camera `side` (or each of several sides, the same data)."""
    import h5py
    from scipy.spatial.transform import Rotation

    folder.mkdir(parents=True, exist_ok=True)
    frames = np.stack([seq.load_frame(k) for k in range(len(seq.frame_times()))])
    data = folder / f"{name}_data.hdf5"
    sides = (side,) if isinstance(side, str) else side
    with h5py.File(data, "w") as f:
        for side in sides:
            g = f.create_group(f"davis/{side}")
            g.create_dataset("events", data=mvsec_rows(np.asarray(seq.events())), **events_options)
            g.create_dataset("image_raw", data=frames, compression="lzf", chunks=(1, *frames.shape[1:]))
            g["image_raw_ts"] = seq.frame_times()
            g["imu"] = np.column_stack([seq.imu.acc, seq.imu.gyro])
            g["imu_ts"] = seq.imu.t
    gt = seq.ground_truth
    T = np.tile(np.eye(4), (len(gt.t), 1, 1))
    T[:, :3, :3] = Rotation.from_quat(gt.q_w_c).as_matrix()
    T[:, :3, 3] = gt.p_w_c
    with h5py.File(folder / f"{name}_gt.hdf5", "w") as f:
        for side in sides:
            g = f.create_group(f"davis/{side}")
            g["pose"] = T
            g["pose_ts"] = gt.t
    return data


def seeded_flips(source: Path, count: int, seed: int) -> list[tuple[str, int, int]]:
    """`count` (file, byte, bit) places to flip in `source` (a file: file "", or a folder: a
    file of it drawn by size), at seeded random bytes."""
    import random

    rng = random.Random(seed)
    names = (
        tuple(sorted(str(p.relative_to(source)) for p in source.rglob("*") if p.is_file()))
        if source.is_dir()
        else ("",)
    )
    sizes = [(source / name).stat().st_size for name in names]
    flips = []
    for _ in range(count):
        name = rng.choices(names, weights=sizes)[0]
        flips.append((name, rng.randrange(sizes[names.index(name)]), rng.randrange(8)))
    return flips


def flipped_copies(source: Path, out: Path, flips: list[tuple[str, int, int]]) -> list[Path]:
    """A copy of `source` (a file, or a folder: copied whole) under `out` for each (file, byte,
    bit) of `flips` (file "" for `source` itself), that bit flipped, named by the flip."""
    import shutil

    copies = []
    for k, (name, at, bit) in enumerate(flips):
        data = bytearray((source / name).read_bytes())
        data[at] ^= 1 << bit
        copy = out / f"flip{k}_{name.replace('/', '_')}_byte{at}_bit{bit}" / source.name
        copy.parent.mkdir(parents=True)
        if source.is_dir():
            shutil.copytree(source, copy)
        (copy / name if name else copy).write_bytes(bytes(data))
        copies.append(copy)
    return copies


def read_each_bounded(locations: list[Path], assignments: list[str] = (), per_read_s: float = 20.0) -> dict[str, str]:
    """Open each location with its dataset plugin and read everything (events, every frame,
    IMU, ground truth) in one child process (read_damaged.py), one after the other; the test
    fails, naming the location, if a read has no answer within `per_read_s` (a spin; the
    child is killed) or the child dies (a crash). Returns {location: "ok" or the error's line}."""
    import json
    import select
    import subprocess
    import sys
    import time

    script = Path(__file__).with_name("read_damaged.py")
    child = subprocess.Popen(
        [sys.executable, str(script), json.dumps([str(p) for p in locations]), *assignments],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        bufsize=1,
    )
    outcomes, current = {}, "(starting)"
    deadline = time.monotonic() + 3 * per_read_s  # the first read also imports the readers
    try:
        while True:
            ready, _, _ = select.select([child.stdout], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                pytest.fail(f"{current}: no answer within {per_read_s} s: the read spins")
            line = child.stdout.readline()
            if not line:
                break
            kind, _, rest = line.rstrip("\n").partition("\t")
            if kind == "start":
                current, deadline = rest, time.monotonic() + per_read_s
            else:
                outcomes[current] = rest
    finally:
        child.kill()
        stderr = child.communicate()[1]
    if child.returncode not in (0, -9) or len(outcomes) < len(locations):
        pytest.fail(f"{current}: the reading process died ({child.returncode}): {stderr[-2000:]}")
    return outcomes


def write_aedat4(path, *, size, events=None, frames=(), imu=None, kind="davis", compression="LZ4", packet=50_000):
    """An AEDAT4 written by dv-processing for a `size` (width, height) sensor. events: (t_us, x,
    y, p) columns, `packet` per packet; frames: (start_us, exposure_us, uint8 image); imu: rows
    (t_us, acc [g] x3, gyro [deg/s] x3)."""
    import dv_processing as dv

    config = {
        "davis": dv.io.MonoCameraWriter.DAVISConfig,
        "events": dv.io.MonoCameraWriter.EventOnlyConfig,
        "frames": dv.io.MonoCameraWriter.FrameOnlyConfig,
    }[kind]("DAVIS_test", size)
    config.compression = dv.CompressionType.__members__[compression]
    writer = dv.io.MonoCameraWriter(str(path), config)
    if events is not None:
        t, x, y, p = (np.asarray(c).tolist() for c in events)
        for start in range(0, len(t), packet):  # the writer checks order between packets only
            events = dv.EventPacket()
            for k in range(start, min(start + packet, len(t))):
                events.elements.append(dv.Event(t[k], x[k], y[k], bool(p[k])))
            writer.writeEventPacket(events)
    for start_us, exposure_us, image in frames:
        writer.writeFrame(dv.Frame(int(start_us), int(exposure_us), 0, 0, image, dv.FrameSource.SENSOR))
    for row in imu if imu is not None else ():
        t_us, ax, ay, az, gx, gy, gz = row
        writer.writeImu(dv.IMU(int(t_us), 25.0, ax, ay, az, gx, gy, gz, 0.0, 0.0, 0.0))
    del writer  # closing writes the file's index


def K_of(cam) -> np.ndarray:
    """The intrinsic matrix of a camera dict (f, c: focal lengths and principal point [px])."""
    (fx, fy), (cx, cy) = cam["f"], cam["c"]
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def write_dv_xml(path, cam, node="DAVIS346_00000499"):
    """As DV's camera(-IMU) calibration module writes it: the camera's node, then the lens model."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.startWriteStruct(node, cv2.FILE_NODE_MAP)
    fs.write("camera_matrix", K_of(cam))
    fs.write("distortion_coefficients", np.array([cam["dist"]]))
    fs.write("image_width", cam["width"])
    fs.write("image_height", cam["height"])
    fs.endWriteStruct()
    fs.write("use_fisheye_model", 0)  # the module writes false whatever the model
    fs.write("type", "camera")
    fs.write("pattern_width", 8)
    fs.write("pattern_height", 6)
    fs.write("distortion_model", "Equidistant" if cam["model"] == "equidistant" else "RadialTangential")
    fs.write("pattern_type", "chessboard")
    fs.write("calibration_error", "N/A")
    fs.write("time_offset_cam_imu__t_imu_equals_t_cam_plus_shift", 0.0021)
    fs.write("transformation_cam_imu", np.eye(4))
    fs.release()
