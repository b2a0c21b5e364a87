"""MVSEC recordings (Zhu et al., "The Multivehicle Stereo Event Camera Dataset", RA-L 2018) in
their HDF5 layout, read with h5py (and, when installed, hdf5plugin's filters for datasets
compressed with blosc, zstd, lz4 or bitshuffle, which HDF5 itself lacks):

    NAME_data.hdf5   davis/{left,right}/
        events         (N, 4) float64   x y t p   (x, y [px], t [s], p in {-1, 1})
        image_raw      (M, H, W) uint8  APS frames
        image_raw_ts   (M,) float64     [s], taken as each frame's time unchanged
        imu            (K, 6) float64   ax ay az [m/s^2], gx gy gz [rad/s] (sensor_msgs/Imu)
        imu_ts         (K,) float64     [s]
    NAME_gt.hdf5     davis/left/
        pose           (L, 4, 4) float64  T_w_c, camera-to-world (the left DAVIS's)
        pose_ts        (L,) float64       [s]

The files hold no intrinsics: MVSEC publishes them as kalibr camchain YAMLs (equidistant lens
model; cam0 the left DAVIS, cam1 the right). Rows are named by their h5py index (from 0).
Frame times are those MVSEC's converter took from its bags (the DAVIS driver stamps a frame
with libcaer's frame time, the middle of its exposure); events and frames share that clock.
"""

from __future__ import annotations

import functools
import mmap
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from eas_vo.camera import CameraModel
from eas_vo.datasets.calibration import MAX_SENSOR_PX, read_calibration
from eas_vo.datasets.recording import RecordingReader, StreamConfig, clock_origin_ns
from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, cache_key, file_identity, load_cached, pack_rows, pack_table, write_behind
from eas_vo.geometry.rotations import quats_from_matrices
from eas_vo.io.tables import check_increasing
from eas_vo.types import ImuSeries, PoseSeries, empty_events
from eas_vo.validation import check_choice, check_range

#: How an HDF5 file begins (its superblock signature; at byte 0 unless a user block precedes it).
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Offsets at which the HDF5 signature may stand (0, then 512 doubling: the user block sizes).
SIGNATURE_OFFSETS = (0, 512, 1024, 2048, 4096)
#: Events read from the file per block: 32 MiB of float64 rows, memory bounded by it.
BLOCK_ROWS = 1 << 20
#: Events checked and packed per block when the events are mapped from the file (see
#: `_map_events`): 8 MiB of rows, 3.4 MB of records handed to the writing thread.
MAP_BLOCK_ROWS = 1 << 18
#: Whether events stored contiguously and unfiltered are mapped from the file (h5py only
#: locates them) rather than read through h5py; off, every file takes h5py's block path.
MAP_EVENTS = True
#: madvise(2)'s MADV_POPULATE_READ (Linux 5.14; Python's mmap module names it from 3.12 on):
#: a block's pages of the map faulted in with one call. None elsewhere.
MADV_POPULATE_READ = getattr(mmap, "MADV_POPULATE_READ", 22 if sys.platform.startswith("linux") else None)
#: MVSEC's kalibr camera of each DAVIS.
KALIBR_CAMERA = {"left": "cam0", "right": "cam1"}
#: What h5py raises on a damaged file or an unreadable dataset (a truncated file, a filter
#: missing); KeyError and ValueError for a broken object header or link.
H5_ERRORS = (OSError, KeyError, ValueError, RuntimeError)


def _said(exc: Exception) -> str:
    """h5py's message, on one line."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


@dataclass(frozen=True)
class MvsecConfig(StreamConfig):
    """StreamConfig plus MVSEC's choices.

    Attributes:
        side: the DAVIS read, `left` or `right` (its group davis/SIDE).
        calibration: default: the one `*camchain*.yaml` beside the data file; its camera
            (calibration_camera) cam0 for left, cam1 for right.
        ground_truth: an MVSEC `_gt.hdf5` or a TUM file; default NAME_gt.hdf5 beside
            NAME_data.hdf5, if it exists.
        width, height: sensor size [px] of a recording without frames (default: MVSEC's DAVIS m346).
    """

    side: str = "left"
    width: int = 346
    height: int = 260

    def validate(self) -> None:
        super().validate()
        check_choice(self, "side", KALIBR_CAMERA)
        check_range(self, "width", 1, MAX_SENSOR_PX)
        check_range(self, "height", 1, MAX_SENSOR_PX)


def _has_signature(path: Path) -> bool:
    """Whether `path` holds an HDF5 superblock signature where one may stand (cheap: a few reads)."""
    try:
        with open(path, "rb") as fh:
            for offset in SIGNATURE_OFFSETS:
                fh.seek(offset)
                if fh.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
                    return True
    except OSError:
        pass
    return False


class MvsecDataset(RecordingReader):
    """An MVSEC `NAME_data.hdf5` (events, frames, IMU of one DAVIS) with its `NAME_gt.hdf5` poses."""

    name = "mvsec"
    description = "MVSEC HDF5 recording: NAME_data.hdf5 (davis/left|right events, image_raw, imu) + NAME_gt.hdf5 poses"
    Config = MvsecConfig

    def __init__(self, location: str | Path, config: MvsecConfig | None = None):
        import h5py

        try:
            import hdf5plugin  # noqa: F401  (registers the filters of compressed datasets: blosc, zstd, lz4...)
        except ImportError:  # optional: _dataset names a filter HDF5 lacks
            pass
        self.config = c = config or MvsecConfig()
        self.path = Path(location)
        self.label = str(self.path)
        self.warnings = DataWarnings()
        self.group = f"davis/{c.side}"
        self.file = self._open(h5py, self.path)
        if self.group not in self.file:
            raise DataError(
                self.path, f"has no group {self.group} (an MVSEC NAME_data.hdf5 holds davis/left and davis/right)"
            )
        side = self.file[self.group]
        self._events_dset = self._dataset(side, "events", 2, 4, "f8") if "events" in side else None
        self._images = self._dataset(side, "image_raw", 3, None, "u1") if "image_raw" in side else None
        if self._events_dset is None and self._images is None:
            raise DataError(self.path, f"{self.group} holds neither events nor image_raw")
        self._times, self._frame_rows = self._read_frame_times()
        self.clock_origin_ns = clock_origin_ns(self._first_time_ns())
        self._origin_s = self.clock_origin_ns / 1e9  # whole seconds: subtracting it is exact
        if self._times is not None:
            self._times = self._times - self._origin_s
        if not self._frame_rows:
            self.no_frames_reason = f"{self.path} has no frames in {self.group}/image_raw (an event-only stream)"
        self.camera = self._read_camera()
        self.imu = self._read_imu()
        self.ground_truth = self._read_ground_truth(h5py)
        self._events: np.ndarray | None = None

    # -- plugin contract ---------------------------------------------------------------

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A path ending in `.hdf5` or `.h5` that holds an HDF5 file with a `davis` group."""
        path = Path(location)
        if path.suffix.lower() not in (".hdf5", ".h5") or not path.is_file() or not _has_signature(path):
            return False
        import h5py

        try:
            with h5py.File(path, "r") as f:
                return isinstance(f.get("davis"), h5py.Group)
        except H5_ERRORS:
            return False

    def load_frame(self, k: int) -> np.ndarray | None:
        if not self._frame_rows:
            return None
        row = self._frame_rows[k]
        try:
            return np.ascontiguousarray(self._images[row])
        except H5_ERRORS as exc:
            raise DataError(self._where("image_raw"), f"cannot read frame {k} ({_said(exc)})", row) from None

    def events(self) -> np.ndarray:
        if self._events is None:
            self._events = empty_events() if self._events_dset is None else self._load_events()
        return self._events

    def time_sources(self) -> dict[str, str]:
        """The HDF5 datasets each stream's times are read from (the ground truth's: NAME_gt.hdf5
        beside, or the dataset.ground_truth file)."""
        gt = self._ground_truth_file()
        return {
            "frame": self._where("image_raw_ts"),
            "event": self._where("events") + " (column t)",
            "IMU": self._where("imu_ts"),
            "ground-truth": str(gt)
            if gt is None or gt.suffix.lower() not in (".hdf5", ".h5")
            else self._where("pose_ts", gt),
        }

    # -- readers -----------------------------------------------------------------------

    @staticmethod
    def _open(h5py, path: Path):
        if not path.is_file():
            raise DataError(path, "file not found")
        try:
            return h5py.File(path, "r")
        except H5_ERRORS as exc:
            raise DataError(path, f"not a readable HDF5 file ({_said(exc)})") from None

    def _where(self, name: str, path: Path | None = None) -> str:
        return f"{path or self.path}:{self.group}/{name}"

    def _dataset(self, group, name: str, ndim: int, columns: int | None, dtype: str, path: Path | None = None):
        """group[name], checked to be an HDF5 dataset of `ndim` dimensions (the last `columns`
        wide) holding `dtype` (float64 for times and measurements, as MVSEC writes them: float32
        would round a time of 1.5e9 s to 128 s)."""
        import h5py

        where = self._where(name, path)
        try:
            dset = group[name]
        except H5_ERRORS as exc:
            raise DataError(where, f"unreadable ({_said(exc)})") from None
        if not isinstance(dset, h5py.Dataset):
            raise DataError(where, "is a group, expected a dataset")
        wanted = np.dtype(dtype)
        dims = dset.shape or ()  # None: a null dataspace (h5py.Empty)
        shape = "null" if dset.shape is None else " x ".join(map(str, dims)) or "scalar"
        expected = f"{ndim} dimensions" + (f", {columns} columns" if columns else "")
        if len(dims) != ndim or (columns and dims[-1] != columns):
            raise DataError(where, f"has shape {shape}, expected {expected}")
        if dset.dtype.newbyteorder("=") != wanted:  # either byte order: HDF5 converts on reading
            raise DataError(where, f"holds {dset.dtype}, expected {wanted}")
        plist = dset.id.get_create_plist()
        for k in range(plist.get_nfilters()):
            code, _, _, name = plist.get_filter(k)
            if not h5py.h5z.filter_avail(code):
                raise DataError(
                    where,
                    f"is compressed with HDF5 filter {code} ({name.decode(errors='replace') or 'unnamed'}), which this "
                    'HDF5 lacks: pip install hdf5plugin (or eas-vo\'s "[hdf5]" extra) adds blosc, zstd, lz4 and bitshuffle',
                )
        return dset

    def _read(self, dset, where: str) -> np.ndarray:
        """A whole (small) dataset in memory; damage is named."""
        try:
            return np.asarray(dset[()], dtype=np.float64)
        except H5_ERRORS as exc:
            raise DataError(where, f"unreadable ({_said(exc)})") from None

    def _timed(self, group, name: str, ndim: int, columns: int | None, path: Path | None = None):
        """(values, times [s]) of `name` and `name_ts`, both finite, as many of each, the times
        increasing (--lenient: rows repeating a time dropped)."""
        values = self._read(self._dataset(group, name, ndim, columns, "f8", path), self._where(name, path))
        ts_where = self._where(name + "_ts", path)
        if name + "_ts" not in group:
            raise DataError(ts_where, f"missing: the times of {self.group}/{name}")
        t = self._read(self._dataset(group, name + "_ts", 1, None, "f8", path), ts_where)
        if len(t) != len(values):
            raise DataError(ts_where, f"holds {len(t)} times for {len(values)} rows of {self.group}/{name}")
        if len(t) < 2:
            raise DataError(self._where(name, path), f"holds {len(t)} row(s); at least 2 are needed to interpolate")
        for data, at in ((t, ts_where), (values.reshape(len(values), -1), self._where(name, path))):
            bad = np.flatnonzero(~np.isfinite(data).reshape(len(data), -1).all(axis=1))
            if len(bad):
                raise DataError(at, "holds a value that is not finite (NaN or infinity)", int(bad[0]))
        keep = check_increasing(ts_where, t, int, self.tolerated, "row")
        return values[keep], t[keep]

    def _read_frame_times(self) -> tuple[np.ndarray | None, list[int]]:
        """The frame times [s] and the image_raw row of each frame kept (lenient: those going back dropped)."""
        if self._images is None or len(self._images) == 0:
            return None, []
        side = self.file[self.group]
        where = self._where("image_raw_ts")
        if "image_raw_ts" not in side:
            raise DataError(where, f"missing: the times of {self.group}/image_raw")
        t = self._read(self._dataset(side, "image_raw_ts", 1, None, "f8"), where)
        if len(t) != len(self._images):
            raise DataError(where, f"holds {len(t)} times for {len(self._images)} frames of {self.group}/image_raw")
        times, rows = [], []
        for row, ti in enumerate(t):
            problem = None
            if not np.isfinite(ti):
                problem = ("timestamp not finite", f"timestamp {ti} is not finite")
            elif times and ti < times[-1]:
                problem = ("timestamp going back", f"timestamp {ti:.9f} goes back (previous {times[-1]:.9f})")
            if problem is not None:
                if not self.config.lenient:
                    raise DataError(where, problem[1], row)
                self.warnings.add(where, problem[0], f"row {row}")
                continue
            times.append(float(ti))
            rows.append(row)
        return np.array(times), rows

    def _sensor_size(self) -> tuple[int, int]:
        """(width, height) [px]: of the frames (image_raw's shape, even when it holds none), else
        the configured ones."""
        if self._images is None:
            return self.config.width, self.config.height
        height, width = self._images.shape[1:]
        if not (1 <= width <= MAX_SENSOR_PX and 1 <= height <= MAX_SENSOR_PX):
            raise DataError(
                self._where("image_raw"),
                f"frames are {width}x{height}, not an event camera's (at most {MAX_SENSOR_PX} px a side)",
            )
        return width, height

    def _read_camera(self) -> CameraModel | None:
        """`dataset.calibration`, else the one kalibr camchain beside the file; None (with the
        reason) for none, or several to choose from."""
        self._sensor = width, height = self._sensor_size()
        side_camera = KALIBR_CAMERA[self.config.side]
        camera = self.calibration_file(width, height, side_camera)
        if camera is not None:
            return camera
        found = sorted(self.path.parent.glob("*camchain*.yaml"))
        if len(found) == 1:
            return read_calibration(
                found[0], width=width, height=height, camera=self.config.calibration_camera or side_camera
            )
        self.no_camera_reason = (
            f"{self.path}: the intrinsics are unknown: an MVSEC HDF5 file holds none; give its kalibr camchain YAML "
            "with --set dataset.calibration=FILE"
            if not found
            else f"{self.path}: {len(found)} camchain YAMLs beside it ({', '.join(p.name for p in found)}); choose one with "
            "--set dataset.calibration=FILE"
        )
        return None

    def _read_imu(self) -> ImuSeries | None:
        side = self.file[self.group]
        if "imu" not in side:
            return None
        table, t = self._timed(side, "imu", 2, 6)
        return ImuSeries(t=t - self._origin_s, acc=table[:, :3], gyro=table[:, 3:])

    def _ground_truth_file(self) -> Path | None:
        if self.config.ground_truth:
            return Path(self.config.ground_truth)
        stem = self.path.stem
        if not stem.endswith("_data"):
            return None
        beside = self.path.with_name(stem[: -len("_data")] + "_gt" + self.path.suffix)
        return beside if beside.is_file() else None

    def _read_ground_truth(self, h5py) -> PoseSeries | None:
        path = self._ground_truth_file()
        if path is None:
            return None
        if path.suffix.lower() not in (".hdf5", ".h5"):
            return self.ground_truth_file()
        with self._open(h5py, path) as f:
            if self.group not in f or "pose" not in f[self.group]:
                if self.config.ground_truth:
                    raise DataError(path, f"has no {self.group}/pose")
                return None  # MVSEC's poses are the left DAVIS's: davis/right has none
            T, t = self._timed(f[self.group], "pose", 3, 4, path)
        where = self._where("pose", path)
        if T.shape[1] != 4:
            raise DataError(where, f"has shape {' x '.join(map(str, T.shape))}, expected L x 4 x 4 (T_w_c)")
        R = T[:, :3, :3]
        off = np.abs(T[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 1e-6
        off |= np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2)) > 1e-2
        off |= np.linalg.det(R) <= 0
        if off.any():
            row = int(np.argmax(off))
            raise DataError(
                where, "is not a rigid transform (rotation not orthonormal with det 1, or last row not 0 0 0 1)", row
            )
        return PoseSeries(
            t=(t - self._origin_s) + self.config.ground_truth_time_offset_s,
            p_w_c=T[:, :3, 3].copy(),
            q_w_c=quats_from_matrices(R),
        )

    def _first_time_ns(self) -> int:
        """The first frame's or event's time [ns] on the file's clock (0 with neither)."""
        firsts = [self._times[0]] if self._times is not None and len(self._times) else []
        if self._events_dset is not None and len(self._events_dset):
            try:
                firsts.append(float(self._events_dset[0, 2]))
            except H5_ERRORS as exc:
                raise DataError(self._where("events"), f"unreadable ({_said(exc)})", 0) from None
        firsts = [t for t in firsts if np.isfinite(t)]
        return int(min(firsts) * 1e9) if firsts else 0

    def _after_origin(self, events: np.ndarray) -> np.ndarray:
        """Packed events (checked on the file's clock) with their times after the clock origin, in place."""
        if self._origin_s:
            events["t"] -= self._origin_s
        return events

    def _load_events(self) -> np.ndarray:
        c = self.config
        dset = self._events_dset
        where = self._where("events")

        def fill(out, warnings):
            validate = Validator(where, *self._sensor, c.time_tolerance_s, c.lenient, warnings, "row")
            mapped = self._map_events(dset) if MAP_EVENTS else None
            if mapped is not None:
                return pack_table(
                    mapped[0],
                    (2, 0, 1, 3),
                    validate,
                    lambda events: out.write(self._after_origin(events)),
                    MAP_BLOCK_ROWS,
                    group_rows=BLOCK_ROWS,
                    touch=mapped[1],
                )
            blocks = (
                functools.partial(lambda block: self._after_origin(block()), block)
                for block in self._h5py_blocks(dset, where, validate)
            )
            return write_behind(out, blocks)

        key = cache_key(
            "mvsec", *file_identity(self.path), self.group, *self._sensor, c.time_tolerance_s, self.clock_origin_ns
        )
        return load_cached(key, c.lenient, self.warnings, fill, where, len(dset))

    def _map_events(self, dset) -> tuple[np.ndarray, Callable[[int, int], None] | None] | None:
        """The (N, 4) event rows as a read-only map of the file's own bytes, when h5py would only
        copy them: one contiguous, unfiltered, fully written block of IEEE float64 (either byte
        order) in a plain file, entirely inside it; with a function that faults the pages of
        rows start..stop-1 in at once (None where madvise cannot). None otherwise: chunked,
        compressed, external or unwritten storage, another file driver, a file shorter than
        its rows' end go through h5py's block path. The file must not shrink while it is read
        (as for any map: the process would be killed by SIGBUS)."""
        import h5py

        try:
            if self.file.driver != "sec2" or dset.id.get_create_plist().get_layout() != h5py.h5d.CONTIGUOUS:
                return None
            if dset.id.get_create_plist().get_external_count() or dset.id.get_create_plist().get_nfilters():
                return None
            h5type = dset.id.get_type()
            orders = [
                order for order, ieee in (("<", h5py.h5t.IEEE_F64LE), (">", h5py.h5t.IEEE_F64BE)) if h5type.equal(ieee)
            ]
            offset, nbytes = dset.id.get_offset(), dset.size * 8
            if not orders or offset is None or nbytes == 0 or dset.id.get_storage_size() != nbytes:
                return None
            with open(self.path, "rb") as fh:
                if os.fstat(fh.fileno()).st_size < offset + nbytes:
                    return None
                start = offset - offset % mmap.ALLOCATIONGRANULARITY
                mapped = mmap.mmap(fh.fileno(), offset + nbytes - start, access=mmap.ACCESS_READ, offset=start)
        except (*H5_ERRORS, OverflowError):
            return None
        row_bytes = dset.shape[1] * 8

        def touch(first: int, stop: int) -> None:
            lo = offset - start + first * row_bytes
            lo -= lo % mmap.PAGESIZE
            try:
                mapped.madvise(MADV_POPULATE_READ, lo, offset - start + stop * row_bytes - lo)
            except OSError:
                pass  # before Linux 5.14: the pages fault in as they are read

        rows = np.frombuffer(mapped, orders[0] + "f8", dset.size, offset - start).reshape(dset.shape)
        return rows, (touch if MADV_POPULATE_READ is not None and hasattr(mapped, "madvise") else None)

    def _h5py_blocks(self, dset, where: str, validate: Validator):
        """Blocks of events read through h5py (whole chunks of a chunked dataset), each checked
        and packed by write_behind's worker while the next is read."""
        n = len(dset)
        chunk = dset.chunks[0] if dset.chunks else 1
        block_rows = max(1, BLOCK_ROWS // chunk) * chunk  # whole chunks per read
        buffers = [np.empty((min(block_rows, n), 4), np.float64) for _ in range(2)]  # read one, pack the other
        for k, start in enumerate(range(0, n, block_rows)):
            rows = buffers[k % 2][: min(block_rows, n - start)]
            try:
                dset.read_direct(rows, np.s_[start : start + len(rows)], np.s_[0 : len(rows)])
            except H5_ERRORS as exc:
                raise DataError(where, f"unreadable from this row on ({_said(exc)})", start) from None
            yield functools.partial(pack_rows, rows, (2, 0, 1, 3), validate, start)
