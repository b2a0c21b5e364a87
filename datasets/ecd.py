"""Event Camera Dataset sequences (Mueggler et al., IJRR 2017) in the text layout,
as an extracted folder or as the dataset's `.zip`, read in place.

    events.txt       t x y p            (p in {0, 1})
    images.txt       t images/frame_XXXXXXXX.png
    groundtruth.txt  t px py pz qx qy qz qw   (camera-to-world)
    imu.txt          t ax ay az gx gy gz
    calib.txt        fx fy cx cy k1 k2 p1 p2 k3
    camchain.yaml    instead of calib.txt, for a lens calib.txt cannot hold (fisheye): a kalibr
                     camchain, its cam0 (docs/camera_models.md)

Without `images.txt` the sequence is an event-only stream, sampled at a fixed
rate or every N events.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Iterable
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

import cv2
import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.datasets import ecd_catalogue
from eas_vo.datasets.calibration import MAX_SENSOR_PX, check_frame_size, parse_ecd_calib, parse_kalibr_camchain
from eas_vo.datasets.recording import RecordingReader, StreamConfig, clock_origin_ns
from eas_vo.datasets.sources import MARKERS, open_source
from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import load_event_text, write_events_text
from eas_vo.io.atomic import atomic_path, write_text_atomic
from eas_vo.io.tables import clock_time, text_bytes, timed_table
from eas_vo.io.tum import parse_tum
from eas_vo.types import ImuSeries, PoseSeries, empty_events
from eas_vo.validation import check_range

#: The calibration of a fisheye sequence in this layout: calib.txt has only the radial-tangential
#: model, so (as fisheye datasets in this layout ship, e.g. UZH-FPV's DAVIS) it is kalibr's camchain.
CAMCHAIN = "camchain.yaml"


@contextmanager
def silenced_stderr():
    """Send what C libraries write to file descriptor 2 to /dev/null for the block (libpng
    prints its own complaint about a damaged PNG; eas-vo's one error line says it instead)."""
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


@dataclass(frozen=True)
class EcdConfig(StreamConfig):
    """StreamConfig plus the sensor size [px] for sequences without frames to read it from
    (default: DAVIS240C)."""

    width: int = 240
    height: int = 180

    def validate(self) -> None:
        super().validate()
        check_range(self, "width", 1, MAX_SENSOR_PX)
        check_range(self, "height", 1, MAX_SENSOR_PX)


def _leaves_folder(name: str) -> bool:
    """Whether a path named inside a dataset points outside it (absolute, or up past its root)."""
    path = PurePosixPath(name.replace("\\", "/"))
    if path.is_absolute() or PureWindowsPath(name).drive:
        return True
    depth = 0
    for part in path.parts:
        depth += -1 if part == ".." else (0 if part == "." else 1)
        if depth < 0:
            return True
    return False


class EcdFolderDataset(RecordingReader):
    """An Event Camera Dataset sequence: an extracted folder or its `.zip`."""

    name = "ecd"
    description = (
        "Event Camera Dataset sequence: folder or .zip (events.txt, images.txt, groundtruth.txt, imu.txt, calib.txt)"
    )
    Config = EcdConfig

    def __init__(self, location: str | Path, config: EcdConfig | None = None):
        self.config = config or EcdConfig()
        if not Path(location).exists() and str(location) in ecd_catalogue.registry():  # ecd:hdr_boxes
            location = ecd_catalogue.fetch(str(location), progress=sys.stderr.isatty())
        self.source = open_source(location)
        self.label = self.source.location
        self.warnings = DataWarnings()
        self._times, self._frame_names = self._read_image_list()
        if not self._frame_names and not self.source.exists("events.txt"):
            raise DataError(self.source.label("images.txt"), "file not found, and there is no events.txt either")
        self.clock_origin_ns = clock_origin_ns(self._first_second() * 10**9)
        self._origin_s = self.clock_origin_ns / 1e9  # whole seconds: subtracting it is exact
        if self._times is not None:
            self._times = self._times - self._origin_s
        self._sensor = width, height = self._sensor_size()
        self.camera = self._read_calib(width, height)
        self.ground_truth = self._read_ground_truth()
        self.imu = self._read_imu()
        self._events: np.ndarray | None = None

    # -- plugin contract ---------------------------------------------------------------

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A folder holding `images.txt` or `events.txt`, or a path ending in `.zip`."""
        path = Path(location)
        return path.suffix.lower() == ".zip" or any((path / marker).is_file() for marker in MARKERS)

    @classmethod
    def catalogue(cls) -> dict[str, str]:
        """The dataset's published sequences and the MD5s of their zips."""
        return ecd_catalogue.registry()

    @classmethod
    def fetch(cls, name: str, folder: str | None = None, progress: bool = False) -> Path:
        return ecd_catalogue.fetch(name, folder, progress)

    def load_frame(self, k: int) -> np.ndarray | None:
        if not self._frame_names:
            return None
        expected = self._sensor
        size = self._png_size(k)  # a PNG of the wrong size is refused before it is decoded
        if size is None or size == expected:
            image = self._decode_frame(k)
            size = image.shape[1], image.shape[0]
        if size != expected:
            raise DataError(
                self.source.label(self._frame_names[k]),
                f"frame {k} is {size[0]}x{size[1]}, expected {expected[0]}x{expected[1]} (images.txt line {self._frame_lines[k]})",
            )
        return image

    def events(self) -> np.ndarray:
        if self._events is None:
            if self.source.exists("events.txt"):
                c = self.config
                self._events = load_event_text(
                    lambda: self.source.open("events.txt"),
                    self.source.identity("events.txt"),
                    self.source.label("events.txt"),
                    *self._sensor,
                    c.time_tolerance_s,
                    c.lenient,
                    self.warnings,
                    self.source.size("events.txt"),
                    self._origin_s,
                )
            else:
                self._events = empty_events()
        return self._events

    def time_sources(self) -> dict[str, str]:
        """The files each stream's times are read from (the ground truth's: groundtruth.txt, or the
        dataset.ground_truth file)."""
        label = self.source.label
        return {
            "frame": label("images.txt"),
            "event": label("events.txt"),
            "IMU": label("imu.txt"),
            "ground-truth": self.config.ground_truth or label("groundtruth.txt"),
        }

    # -- readers -----------------------------------------------------------------------

    def _first_second(self) -> int:
        """The whole second [s] of the earlier of the first event line's time and the first frame
        time (0 when neither can be read: the readers then name what is wrong). The earlier: a
        stream in a smaller unit (microseconds of Unix time, 1.7e15) then keeps the others'
        digits, so that its span can be told from theirs."""
        firsts = [float(self._times[0])] if self._times is not None and len(self._times) else []
        if self.source.exists("events.txt"):
            with self.source.open("events.txt") as fh:
                head = fh.read(1 << 16)
            for line in head.splitlines():
                fields = line.split()
                if fields and not fields[0].startswith(b"#"):
                    try:
                        firsts.append(float(fields[0]))
                    except ValueError:
                        pass
                    break
        firsts = [t for t in firsts if math.isfinite(t)]
        return math.floor(min(firsts)) if firsts else 0

    def _read_image_list(self) -> tuple[np.ndarray | None, list[str]]:
        self._frame_lines: list[int] = []
        if not self.source.exists("images.txt"):
            self.no_frames_reason = f"{self.source.label('images.txt')} does not exist (an event-only stream)"
            return None, []
        where = self.source.label("images.txt")
        times, names, lines = [], [], []
        for lineno, line in enumerate(
            text_bytes(self.source.read_bytes("images.txt")).decode(errors="replace").splitlines(), 1
        ):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            problem = self._image_line_problem(parts, times)
            if problem is None and _leaves_folder(parts[1]):
                problem = (
                    "frame outside the dataset",
                    f"frame path {parts[1]} leaves the dataset folder (absolute or '..')",
                )
            if problem is None and not self.source.exists(parts[1]):
                problem = ("missing frame file", f"frame file {parts[1]} does not exist")
            if problem is not None:
                if not self.config.lenient:
                    raise DataError(where, problem[1], lineno)
                self.warnings.add(where, problem[0], f"line {lineno}")
                continue
            times.append(float(parts[0]))
            names.append(parts[1])
            lines.append(lineno)
        self._frame_lines = lines
        return np.array(times, dtype=float), names

    @staticmethod
    def _image_line_problem(parts: list[str], times: list[float]) -> tuple[str, str] | None:
        """(kind, message) of what is wrong with an images.txt line, or None."""
        if len(parts) != 2:
            return "malformed line", f"expected 't path', found {len(parts)} fields"
        try:
            t = float(parts[0])
        except ValueError:
            return "malformed line", f"timestamp {parts[0]!r} is not a number"
        if not math.isfinite(t):
            return "malformed line", "timestamp is not finite"
        if times and t < times[-1]:
            return "timestamp going back", f"timestamp {t:.9f} goes back (previous {times[-1]:.9f})"
        return None

    def _sensor_size(self) -> tuple[int, int]:
        """(width, height) of the frames: the size most of the first three have (from the PNG
        header, before decoding), so one odd first frame is blamed, not the good ones after it."""
        if not self._frame_names:
            return self.config.width, self.config.height
        sizes = [self._frame_size(k) for k in range(min(3, len(self._frame_names)))]
        for k, size in enumerate(sizes):
            if not (1 <= size[0] <= MAX_SENSOR_PX and 1 <= size[1] <= MAX_SENSOR_PX):
                raise DataError(
                    self.source.label(self._frame_names[k]),
                    f"frame {k} is {size[0]}x{size[1]}, not an event camera's frame (at most "
                    f"{MAX_SENSOR_PX} px a side; images.txt line {self._frame_lines[k]})",
                )
        common = max(set(sizes), key=sizes.count)
        for k, size in enumerate(sizes):
            if size != common:
                raise DataError(
                    self.source.label(self._frame_names[k]),
                    f"frame {k} is {size[0]}x{size[1]} where the frames after it are {common[0]}x{common[1]} "
                    f"(images.txt line {self._frame_lines[k]})",
                )
        return common

    def _frame_size(self, k: int) -> tuple[int, int]:
        """(width, height) of frame k: from its PNG header if it is one, else decoded."""
        size = self._png_size(k)
        if size is None:
            image = self._decode_frame(k)
            size = image.shape[1], image.shape[0]
        return size

    def _png_size(self, k: int) -> tuple[int, int] | None:
        """(width, height) from frame k's PNG header (its first 24 bytes), None if not a PNG."""
        with self.source.open(self._frame_names[k]) as f:
            head = f.read(24)
        if len(head) == 24 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
            return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
        return None

    def _decode_frame(self, k: int) -> np.ndarray:
        name = self._frame_names[k]
        data = np.frombuffer(self.source.read_bytes(name), np.uint8)
        image = None
        if data.size:  # OpenCV asserts on an empty buffer instead of returning None
            with silenced_stderr():  # a damaged PNG: libpng's own line would come before ours
                try:
                    image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
                except cv2.error:  # a header OpenCV refuses (e.g. a size beyond its limits)
                    pass
        if image is None:
            empty = ": the file is empty" if not data.size else ""
            raise DataError(
                self.source.label(name), f"cannot decode frame {k}{empty} (images.txt line {self._frame_lines[k]})"
            )
        return image

    def _read_calib(self, width: int, height: int) -> CameraModel | None:
        given = self.calibration_file(width, height)
        if given is not None:
            return given
        where = self.source.label("calib.txt")
        if not self.source.exists("calib.txt"):
            if self.source.exists(CAMCHAIN):
                return self._read_camchain(width, height)
            self.no_camera_reason = (
                f"{where}: file not found: calib.txt holds the intrinsics 'fx fy cx cy k1 k2 p1 p2 "
                f"k3' (or {CAMCHAIN}, a kalibr camchain, those of a fisheye; or give one with "
                "--set dataset.calibration=FILE)"
            )
            return None
        camera = parse_ecd_calib(text_bytes(self.source.read_bytes("calib.txt")), where, width, height)
        if self.source.exists(CAMCHAIN):
            _refuse_disagreement(camera, where, self._read_camchain(width, height), self.source.label(CAMCHAIN))
        return camera

    def _read_camchain(self, width: int, height: int) -> CameraModel:
        """cam0 of the folder's kalibr camchain (calibration.parse_kalibr_camchain), for the frames' size."""
        where = self.source.label(CAMCHAIN)
        camera = parse_kalibr_camchain(text_bytes(self.source.read_bytes(CAMCHAIN)), where)
        check_frame_size(
            camera,
            width,
            height,
            where,
            "the frames are" if self._frame_names else "dataset.width x dataset.height is",
            "cam0.resolution",
        )
        return camera

    def _read_ground_truth(self) -> PoseSeries | None:
        if self.config.ground_truth:
            return self.ground_truth_file()
        if not self.source.exists("groundtruth.txt"):
            return None
        return parse_tum(
            self.source.read_bytes("groundtruth.txt"),
            self.source.label("groundtruth.txt"),
            self.config.ground_truth_time_offset_s,
            self.clock_origin_ns,
            self.tolerated,
            min_poses=2,
        )

    def _read_imu(self) -> ImuSeries | None:
        if not self.source.exists("imu.txt"):
            return None
        table, _ = timed_table(
            self.source.read_bytes("imu.txt"), self.source.label("imu.txt"), 7, "t ax ay az gx gy gz", self.tolerated
        )
        return ImuSeries(t=table[:, 0] - self._origin_s, acc=table[:, 1:4], gyro=table[:, 4:7])


def _refuse_disagreement(camera: CameraModel, where: str, other: CameraModel, other_where: str) -> None:
    """A DataError when the two calibrations of one folder's camera differ in lens model,
    intrinsics or distortion (beyond the 12 significant digits the writer prints): nothing
    says which one is right, and a wrong one bends every rotation, so neither is used."""
    names = ("fx", "fy", "cx", "cy")
    mine = dict(zip(names, camera.K[[0, 1, 0, 1], [0, 1, 2, 2]]))
    theirs = dict(zip(names, other.K[[0, 1, 0, 1], [0, 1, 2, 2]]))
    if camera.model != other.model:
        differs = f"lens model {camera.model} against {other.model}"
    else:
        key = next((k for k in names if not np.isclose(mine[k], theirs[k], rtol=1e-9, atol=0.0)), None)
        same_dist = len(camera.dist) == len(other.dist) and np.allclose(camera.dist, other.dist, rtol=1e-9, atol=1e-12)
        if key is None and same_dist:
            return
        differs = (
            f"{key} {mine[key]:g} against {theirs[key]:g}"
            if key is not None
            else f"distortion {' '.join(f'{v:g}' for v in camera.dist)} against {' '.join(f'{v:g}' for v in other.dist)}"
        )
    raise DataError(
        f"{where} and {other_where}",
        f"two calibrations of the camera that differ ({differs}); remove the "
        "wrong one, or choose one with --set dataset.calibration=FILE",
    )


def write_ecd_folder(
    root: str | Path,
    camera: CameraModel,
    frame_times: np.ndarray,
    frames: Iterable[np.ndarray] | None,
    events: np.ndarray,
    ground_truth: PoseSeries | None = None,
    imu: ImuSeries | None = None,
    origin_ns: int = 0,
) -> None:
    """Write a sequence in the Event Camera Dataset text layout (each file atomically); the
    calibration as calib.txt, or for a fisheye as CAMCHAIN. Times [s] are after the clock origin
    `origin_ns` (Dataset.clock_origin_ns), written as the recording's own.

    `frames`: the uint8 frame at each of `frame_times` [s], taken one at a time (a generator
    keeps one in memory); None for an event-only stream (no images/ nor images.txt)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    lines = []
    for k, (t, frame) in enumerate(zip(frame_times, () if frames is None else frames)):
        name = f"images/frame_{k:08d}.png"
        with atomic_path(root / name) as tmp:
            tmp.write_bytes(cv2.imencode(".png", frame)[1].tobytes())
        lines.append(f"{clock_time(t, origin_ns)} {name}")
    if camera.model == "radtan":
        write_text_atomic(root / "calib.txt", " ".join(f"{v:.12g}" for v in camera.calib_values()) + "\n")
    else:
        write_text_atomic(root / CAMCHAIN, camchain_yaml(camera))
    if ground_truth is not None:
        table = np.column_stack([ground_truth.p_w_c, ground_truth.q_w_c])
        write_text_atomic(root / "groundtruth.txt", _format_rows(ground_truth.t, table, origin_ns))
    if imu is not None:
        write_text_atomic(root / "imu.txt", _format_rows(imu.t, np.column_stack([imu.acc, imu.gyro]), origin_ns))
    write_events_text(root / "events.txt", events, camera.width, camera.height, origin_ns=origin_ns)
    if frames is not None:  # images.txt last: a folder is complete only once its frame list exists.
        write_text_atomic(root / "images.txt", "\n".join(lines) + "\n")


def camchain_yaml(camera: CameraModel) -> str:
    """An equidistant `camera` as cam0 of a kalibr camchain (kalibr's radtan has no k3: those
    go into calib.txt)."""
    if camera.model != "equidistant":
        raise ValueError(f"{camera.model} cameras go into calib.txt")
    K = camera.K
    return (
        f"# written by eas-vo: the camera of this sequence, in kalibr's camchain format\n"
        f"cam0:\n  camera_model: pinhole\n"
        f"  intrinsics: [{', '.join(repr(float(v)) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))}]\n"
        f"  distortion_model: {camera.model}\n"
        f"  distortion_coeffs: [{', '.join(repr(float(v)) for v in camera.dist)}]\n"
        f"  resolution: [{camera.width}, {camera.height}]\n"
    )


def _format_rows(t: np.ndarray, table: np.ndarray, origin_ns: int) -> str:
    """Rows `t v1 v2 ...`, t [s] after the clock origin written as the recording's own time."""
    return "".join(
        " ".join([clock_time(ti, origin_ns), *(f"{v:.9f}" for v in row)]) + "\n" for ti, row in zip(t, table)
    )
