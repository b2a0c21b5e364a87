"""Event Camera Dataset folders (Mueggler et al., IJRR 2017), text layout.

    events.txt       t x y p            (p in {0, 1})
    images.txt       t images/frame_XXXXXXXX.png
    groundtruth.txt  t px py pz qx qy qz qw   (camera-to-world)
    imu.txt          t ax ay az gx gy gz
    calib.txt        fx fy cx cy k1 k2 p1 p2 k3
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from eas_vo.config import check_range
from eas_vo.errors import DataError
from eas_vo.io import atomic_path, load_events, read_table, write_events_text, write_text_atomic
from eas_vo.plugins import Dataset
from eas_vo.types import CameraModel, ImuSeries, PoseSeries, empty_events


@dataclass(frozen=True)
class EcdConfig:
    """Sensor size [px] used when the folder has no frames to read it from (DAVIS240C default)."""

    width: int = 240
    height: int = 180

    def validate(self) -> None:
        check_range(self, "width", 1, 65535)
        check_range(self, "height", 1, 65535)


class EcdFolderDataset(Dataset):
    """A folder in the Event Camera Dataset's text layout (frames, events, ground truth, IMU)."""

    name = "ecd"
    description = "Event Camera Dataset folder (events.txt, images.txt, groundtruth.txt, imu.txt, calib.txt)"
    Config = EcdConfig

    def __init__(self, root: str | Path, config: EcdConfig | None = None):
        self.config = config or EcdConfig()
        self.root = Path(root)
        self.description = str(self.root)
        if not self.root.is_dir():
            raise DataError(self.root, "dataset folder not found")
        self._times, self._paths = self._read_image_list()
        width, height = self._sensor_size()
        self.camera = self._read_calib(width, height)
        self.ground_truth = self._read_ground_truth()
        self.imu = self._read_imu()
        self._events: np.ndarray | None = None

    # -- plugin protocol ---------------------------------------------------------------

    def frame_times(self) -> np.ndarray:
        return self._times

    def load_frame(self, k: int) -> np.ndarray | None:
        path = self._paths[k]
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise DataError(path, f"cannot read frame {k} (listed in images.txt line {k + 1})")
        if image.shape != (self.camera.height, self.camera.width):
            raise DataError(
                path,
                f"frame {k} is {image.shape[1]}x{image.shape[0]}, "
                f"expected {self.camera.width}x{self.camera.height}",
            )
        return image

    def events(self) -> np.ndarray:
        if self._events is None:
            path = self.root / "events.txt"
            if path.exists():
                self._events = load_events(path, self.camera.width, self.camera.height)
            else:
                self._events = empty_events()
        return self._events

    # -- readers -----------------------------------------------------------------------

    def _read_image_list(self) -> tuple[np.ndarray, list[Path]]:
        listing = self.root / "images.txt"
        if not listing.exists():
            raise DataError(listing, "file not found: an Event Camera Dataset folder needs images.txt")
        times, paths = [], []
        for lineno, line in enumerate(listing.read_text(errors="replace").splitlines(), start=1):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            if len(parts) != 2:
                raise DataError(listing, f"expected 't path', found {len(parts)} fields", lineno)
            try:
                t = float(parts[0])
            except ValueError:
                raise DataError(listing, f"timestamp {parts[0]!r} is not a number", lineno) from None
            if not math.isfinite(t):
                raise DataError(listing, "timestamp is not finite", lineno)
            if times and t <= times[-1]:
                raise DataError(listing, f"timestamp {t:.9f} does not increase (previous {times[-1]:.9f})", lineno)
            path = self.root / parts[1]
            if not path.is_file():
                raise DataError(listing, f"frame file {parts[1]} does not exist", lineno)
            times.append(t)
            paths.append(path)
        return np.array(times, dtype=float), paths

    def _sensor_size(self) -> tuple[int, int]:
        if self._paths:
            first = cv2.imread(str(self._paths[0]), cv2.IMREAD_GRAYSCALE)
            if first is None:
                raise DataError(self._paths[0], "cannot read frame 0 (listed in images.txt line 1)")
            return first.shape[1], first.shape[0]
        return self.config.width, self.config.height

    def _read_calib(self, width: int, height: int) -> CameraModel:
        path = self.root / "calib.txt"
        if not path.exists():
            raise DataError(path, "file not found: calib.txt holds the intrinsics 'fx fy cx cy k1 k2 p1 p2 k3'")
        fields = path.read_text(errors="replace").split()
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise DataError(path, "calibration values must be numbers", 1) from None
        if len(values) not in (4, 8, 9) or not all(map(math.isfinite, values)):
            raise DataError(path, f"expected 4, 8 or 9 finite values (fx fy cx cy k1 k2 p1 p2 k3), found {len(values)}", 1)
        return CameraModel.from_calib(values, width, height)

    def _read_ground_truth(self) -> PoseSeries | None:
        path = self.root / "groundtruth.txt"
        if not path.exists():
            return None
        table = read_table(path, 8, "t px py pz qx qy qz qw")
        _check_increasing(path, table[:, 0])
        q = table[:, 4:8]
        norms = np.linalg.norm(q, axis=1)
        if (np.abs(norms - 1.0) > 1e-2).any():
            i = int(np.argmax(np.abs(norms - 1.0) > 1e-2))
            raise DataError(path, f"quaternion norm {norms[i]:.3f} is not 1", i + 1)
        return PoseSeries(t=table[:, 0], p_w_c=table[:, 1:4], q_w_c=q / norms[:, None])

    def _read_imu(self) -> ImuSeries | None:
        path = self.root / "imu.txt"
        if not path.exists():
            return None
        table = read_table(path, 7, "t ax ay az gx gy gz")
        _check_increasing(path, table[:, 0])
        return ImuSeries(t=table[:, 0], acc=table[:, 1:4], gyro=table[:, 4:7])


def _check_increasing(path: Path, t: np.ndarray) -> None:
    bad = np.flatnonzero(np.diff(t) <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        raise DataError(path, f"timestamp {t[i]:.9f} does not increase (previous {t[i - 1]:.9f})", i + 1)


def write_ecd_folder(
    root: str | Path,
    camera: CameraModel,
    frame_times: np.ndarray,
    frames: list[np.ndarray],
    events: np.ndarray,
    ground_truth: PoseSeries | None = None,
    imu: ImuSeries | None = None,
) -> None:
    """Write a sequence in the Event Camera Dataset text layout (each file atomically)."""
    root = Path(root)
    (root / "images").mkdir(parents=True, exist_ok=True)
    lines = []
    for k, (t, frame) in enumerate(zip(frame_times, frames)):
        name = f"images/frame_{k:08d}.png"
        with atomic_path(root / name) as tmp:
            _, buf = cv2.imencode(".png", frame)
            tmp.write_bytes(buf.tobytes())
        lines.append(f"{t:.9f} {name}")
    write_text_atomic(root / "calib.txt", " ".join(f"{v:.12g}" for v in camera.calib_values()) + "\n")
    if ground_truth is not None:
        table = np.column_stack([ground_truth.t, ground_truth.p_w_c, ground_truth.q_w_c])
        write_text_atomic(root / "groundtruth.txt", _format_rows(table, "%.9f"))
    if imu is not None:
        table = np.column_stack([imu.t, imu.acc, imu.gyro])
        write_text_atomic(root / "imu.txt", _format_rows(table, "%.9f"))
    write_events_text(root / "events.txt", events)
    # images.txt last: a folder is complete only once its frame list exists.
    write_text_atomic(root / "images.txt", "\n".join(lines) + "\n")


def _format_rows(table: np.ndarray, fmt: str) -> str:
    return "".join(" ".join(fmt % v for v in row) + "\n" for row in table)
