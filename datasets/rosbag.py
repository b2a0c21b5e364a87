"""ROS1 bags of the Event Camera Dataset, read with `rosbags` (no ROS install needed).

Topics (configurable): `/dvs/events` (dvs_msgs/EventArray), `/dvs/image_raw`
(sensor_msgs/Image), `/dvs/imu` (sensor_msgs/Imu), `/optitrack/davis`
(geometry_msgs/PoseStamped), `/dvs/camera_info` (sensor_msgs/CameraInfo).
Event arrays are decoded straight from their serialised bytes with numpy.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import cv2
import numpy as np

from eas_vo.datasets.calibration import camera_from_camera_info
from eas_vo.datasets.recording import StreamConfig, check_increasing, event_sample_times, pose_series
from eas_vo.errors import DataError, DataWarnings
from eas_vo.eventfile import Validator, cache_key, file_identity, load_cached
from eas_vo.plugins import Dataset
from eas_vo.types import CameraModel, ImuSeries, empty_events

EVENT_MSG = """
uint16 x
uint16 y
time ts
bool polarity
"""
EVENT_ARRAY_MSG = """
Header header
uint32 height
uint32 width
dvs_msgs/Event[] events
"""
#: The sensor_msgs/CameraInfo distortion_model a lens model is written as.
ROS_DISTORTION_NAMES = {"radtan": "plumb_bob", "equidistant": "equidistant"}
#: What rosbags' reader raises on damaged bytes besides its ReaderError: failed asserts, unknown
#: connection ids, undecodable header text, short reads of its own parsing, and what the chunk
#: decompressors raise (bz2: OSError, EOFError, ValueError; lz4: RuntimeError).
DAMAGED_BAG_ERRORS = (AssertionError, KeyError, IndexError, ValueError, struct.error, OSError, EOFError, RuntimeError)
#: Serialised dvs_msgs/Event: x, y, ts.sec, ts.nsec, polarity (13 bytes, packed).
_EVENT_WIRE = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])


def _said(exc: Exception) -> str:
    """What the reader said of damaged bytes; nothing for its failed asserts and lookups."""
    return "" if isinstance(exc, (AssertionError, KeyError)) else str(exc)


@cache
def typestore():
    """ROS1 Noetic message types plus dvs_msgs."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(EVENT_MSG, "dvs_msgs/msg/Event"))
    store.register(get_types_from_msg(EVENT_ARRAY_MSG, "dvs_msgs/msg/EventArray"))
    return store


def stamp_seconds(sec, nsec) -> np.ndarray:
    """ROS time -> float64 seconds, the nearest double to `sec.nsec` written in decimal."""
    return (np.asarray(sec, np.int64) * 1_000_000_000 + np.asarray(nsec, np.int64)) / 1e9


def decode_event_array(raw: bytes) -> np.ndarray:
    """Serialised dvs_msgs/EventArray -> wire records (x, y, sec, nsec, p)."""
    frame_id_len = int(np.frombuffer(raw, "<u4", 1, 12)[0])
    offset = 16 + frame_id_len + 8
    count = int(np.frombuffer(raw, "<u4", 1, offset)[0])
    if len(raw) != offset + 4 + count * _EVENT_WIRE.itemsize:
        raise ValueError(f"{count} events announced, {len(raw) - offset - 4} bytes of event data")
    return np.frombuffer(raw, _EVENT_WIRE, count, offset + 4)


@dataclass(frozen=True)
class BagConfig(StreamConfig):
    """StreamConfig plus the topic names (the sensor size comes from camera_info)."""

    events_topic: str = "/dvs/events"
    image_topic: str = "/dvs/image_raw"
    imu_topic: str = "/dvs/imu"
    pose_topic: str = "/optitrack/davis"
    camera_info_topic: str = "/dvs/camera_info"


class RosbagDataset(Dataset):
    """A ROS1 `.bag` recorded by the DAVIS driver (frames, events, IMU, motion capture)."""

    name = "rosbag"
    description = "ROS1 .bag (dvs_msgs events, sensor_msgs images/IMU/camera_info, mocap poses)"
    Config = BagConfig

    def __init__(self, location: str | Path, config: BagConfig | None = None):
        from rosbags.rosbag1 import Reader, ReaderError

        self.config = c = config or BagConfig()
        self.path = Path(location)
        self.label = str(self.path)
        self.warnings = DataWarnings()
        if not self.path.is_file():
            raise DataError(self.path, "bag file not found")
        try:
            self.reader = Reader(self.path)
            self.reader.open()
        except (ReaderError, *DAMAGED_BAG_ERRORS) as exc:
            raise DataError(self.path, f"not a readable ROS1 bag ({_said(exc) or 'a damaged index'})") from None
        self.topics = {conn.topic for conn in self.reader.connections}
        self._times, self._frames = self._read_images()
        if not self._frames:
            self.no_frames_reason = f"{self.path} has no {c.image_topic} messages (an event-only stream)"
        self.camera = self._read_camera()
        self.ground_truth = self._read_poses()
        self.imu = self._read_imu()
        self._events = None

    def _messages(self, topic: str, msgtype: str, deserialize: bool = True):
        """(index, message or raw bytes) of a topic; a message that fails to decode names topic and index."""
        connections = [conn for conn in self.reader.connections if conn.topic == topic]
        if not connections:
            return  # (an empty selection would mean every topic to rosbags)
        for conn in connections:
            if conn.msgtype != msgtype:
                raise DataError(self.path, f"topic {topic} carries {conn.msgtype}, expected {msgtype}")
        for index, (conn, raw) in enumerate(self._records(topic, connections)):
            if not deserialize:
                yield index, raw
                continue
            try:
                yield index, typestore().deserialize_ros1(raw, conn.msgtype)
            except Exception as exc:  # rosbags raises assorted errors on damaged data
                raise DataError(f"{self.path}:{topic}", f"cannot decode message ({exc})", index) from None

    def _records(self, topic: str, connections: list):
        """(connection, raw bytes) of each message of `connections`, in time order; damaged bag
        bytes name the topic, the message's index in it and its bag time."""
        from rosbags.rosbag1 import ReaderError

        records = self.reader.messages(connections=connections)
        index = 0
        while True:
            try:
                conn, _, raw = next(records)
            except StopIteration:
                return
            except (ReaderError, *DAMAGED_BAG_ERRORS) as exc:
                t_ns = sorted(entry.time for c in connections for entry in self.reader.indexes[c.id])[index]
                raise DataError(f"{self.path}:{topic}", f"damaged bag data, message unreadable at bag time "
                                                        f"{t_ns / 1e9:.6f} s" + (f" ({_said(exc)})" if _said(exc) else ""),
                                index) from None
            yield conn, raw
            index += 1

    def _read_images(self):
        times, frames = [], []
        where = f"{self.path}:{self.config.image_topic}"
        for index, msg in self._messages(self.config.image_topic, "sensor_msgs/msg/Image"):
            image = np.frombuffer(msg.data, np.uint8)
            channels = {"mono8": 1, "8UC1": 1, "bgr8": 3, "rgb8": 3}.get(msg.encoding)
            if channels is None or len(image) != msg.height * msg.step or msg.step < msg.width * channels:
                raise DataError(where, f"unsupported or inconsistent image ({msg.encoding}, {msg.width}x{msg.height})", index)
            image = image.reshape(msg.height, msg.step)[:, : msg.width * channels].reshape(msg.height, msg.width, channels)
            image = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY if msg.encoding == "rgb8" else cv2.COLOR_BGR2GRAY) if channels == 3 else image[..., 0]
            t = float(stamp_seconds(msg.header.stamp.sec, msg.header.stamp.nanosec))
            if times and t < times[-1]:
                if not self.config.lenient:
                    raise DataError(where, f"timestamp {t:.9f} goes back (previous {times[-1]:.9f})", index)
                self.warnings.add(where, "timestamp going back", f"message {index}")
                continue
            times.append(t)
            frames.append(np.ascontiguousarray(image))
        return (np.array(times) if frames else None), frames

    def _read_camera(self) -> CameraModel:
        c = self.config
        for index, msg in self._messages(c.camera_info_topic, "sensor_msgs/msg/CameraInfo"):
            where = f"{self.path}:{c.camera_info_topic}:{index}"
            return camera_from_camera_info(where, int(msg.width), int(msg.height), msg.K, msg.D, msg.distortion_model)
        raise DataError(self.path, f"no {c.camera_info_topic} message: the camera intrinsics are unknown")

    def _read_poses(self):
        topic = self.config.pose_topic
        rows = [
            (float(stamp_seconds(m.header.stamp.sec, m.header.stamp.nanosec)), m.pose.position.x, m.pose.position.y,
             m.pose.position.z, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w)
            for _, m in self._messages(topic, "geometry_msgs/msg/PoseStamped")
        ]
        if not rows:
            return None
        check_increasing(f"{self.path}:{topic}", np.array(rows)[:, 0])
        return pose_series(f"{self.path}:{topic}", np.array(rows))

    def _read_imu(self):
        topic = self.config.imu_topic
        rows = [
            (float(stamp_seconds(m.header.stamp.sec, m.header.stamp.nanosec)), m.linear_acceleration.x,
             m.linear_acceleration.y, m.linear_acceleration.z, m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z)
            for _, m in self._messages(topic, "sensor_msgs/msg/Imu")
        ]
        if not rows:
            return None
        table = np.array(rows)
        check_increasing(f"{self.path}:{topic}", table[:, 0])
        return ImuSeries(table[:, 0], table[:, 1:4], table[:, 4:7])

    # -- plugin contract ---------------------------------------------------------------

    @classmethod
    def can_open(cls, location: str) -> bool:
        """A path ending in `.bag`."""
        return Path(location).suffix.lower() == ".bag"

    def data_warnings(self) -> list[str]:
        return self.warnings.lines()

    def frame_times(self) -> np.ndarray:
        if self._times is None:
            c = self.config
            self._times = event_sample_times(self.events()["t"], c.sample_rate_hz, c.sample_every_events)
        return self._times

    def load_frame(self, k: int):
        return self._frames[k] if self._frames else None

    def events(self) -> np.ndarray:
        if self._events is None:
            self._events = self._load_events()
        return self._events

    def _load_events(self) -> np.ndarray:
        c = self.config
        topic = c.events_topic
        if topic not in self.topics:
            return empty_events()
        where = f"{self.path}:{topic}"

        def fill(out, warnings):
            validate = Validator(where, self.camera.width, self.camera.height, c.time_tolerance_s, c.lenient, warnings, "message")
            total = 0
            for index, raw in self._messages(topic, "dvs_msgs/msg/EventArray", deserialize=False):
                try:
                    wire = decode_event_array(raw)
                except (ValueError, IndexError) as exc:
                    if not c.lenient:
                        raise DataError(where, f"cannot decode event array ({exc})", index) from None
                    warnings.add(where, "undecodable event array", f"message {index}")
                    continue
                columns = (wire[k].astype(np.int64) for k in ("x", "y", "p"))
                events = validate(stamp_seconds(wire["sec"], wire["nsec"]), *columns, lambda row: index)
                out.write(events.tobytes())
                total += len(events)
            return total

        key = cache_key("bag", *file_identity(self.path), topic, self.camera.width, self.camera.height, c.time_tolerance_s)
        return load_cached(key, c.lenient, self.warnings, fill, where)


def _serialise_event_array(store, t_header: float, width: int, height: int, events: np.ndarray) -> bytes:
    """dvs_msgs/EventArray bytes, built with numpy (millions of events stay fast)."""
    sec, nsec = divmod(int(round(t_header * 1e9)), 1_000_000_000)
    wire = np.empty(len(events), _EVENT_WIRE)
    ns = np.round(events["t"] * 1e9).astype(np.int64)
    wire["sec"], wire["nsec"] = np.divmod(ns, 1_000_000_000)
    wire["x"], wire["y"], wire["p"] = events["x"], events["y"], events["p"] > 0
    head = np.array([0, sec, nsec, 0, height, width, len(events)], "<u4").tobytes()
    return head + wire.tobytes()


def write_bag(dataset: Dataset, path: str | Path, config: BagConfig | None = None, events_per_message: int = 5000) -> None:
    """Write a dataset (frames, events, IMU, ground truth, camera info) as a ROS1 bag."""
    from rosbags.rosbag1 import Writer

    c = config or BagConfig()
    store = typestore()
    T = store.types
    cam = dataset.camera

    def header(t: float):
        sec, nsec = divmod(int(round(t * 1e9)), 1_000_000_000)
        return T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="davis")

    def vec(x, y, z):
        return T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    messages = []  # (t, topic, msgtype, bytes)
    t0 = float(dataset.frame_times()[0]) if len(dataset.frame_times()) else 0.0
    K = cam.K
    info = T["sensor_msgs/msg/CameraInfo"](
        header=header(t0), height=cam.height, width=cam.width, distortion_model=ROS_DISTORTION_NAMES[cam.model],
        D=np.asarray(cam.dist, float), K=np.asarray(K, float).ravel(), R=np.eye(3).ravel(),
        P=np.column_stack([K, np.zeros(3)]).ravel().astype(float), binning_x=0, binning_y=0,
        roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )
    messages.append((t0, c.camera_info_topic, "sensor_msgs/msg/CameraInfo", store.serialize_ros1(info, "sensor_msgs/msg/CameraInfo")))
    for k, t in enumerate(dataset.frame_times()):
        frame = dataset.load_frame(k)
        if frame is None:
            break
        msg = T["sensor_msgs/msg/Image"](header=header(t), height=frame.shape[0], width=frame.shape[1], encoding="mono8",
                                         is_bigendian=0, step=frame.shape[1], data=np.ascontiguousarray(frame).ravel())
        messages.append((t, c.image_topic, "sensor_msgs/msg/Image", store.serialize_ros1(msg, "sensor_msgs/msg/Image")))
    events = dataset.events()
    for start in range(0, len(events), events_per_message):
        chunk = events[start : start + events_per_message]
        t = float(chunk["t"][-1])
        messages.append((t, c.events_topic, "dvs_msgs/msg/EventArray", _serialise_event_array(store, t, cam.width, cam.height, chunk)))
    if dataset.imu is not None:
        zero_cov = np.zeros(9)
        for t, acc, gyro in zip(dataset.imu.t, dataset.imu.acc, dataset.imu.gyro):
            msg = T["sensor_msgs/msg/Imu"](
                header=header(t), orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=zero_cov, angular_velocity=vec(*gyro), angular_velocity_covariance=zero_cov,
                linear_acceleration=vec(*acc), linear_acceleration_covariance=zero_cov,
            )
            messages.append((t, c.imu_topic, "sensor_msgs/msg/Imu", store.serialize_ros1(msg, "sensor_msgs/msg/Imu")))
    gt = dataset.ground_truth
    if gt is not None:
        for t, p, q in zip(gt.t, gt.p_w_c, gt.q_w_c):
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])),
                orientation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
            )
            msg = T["geometry_msgs/msg/PoseStamped"](header=header(t), pose=pose)
            messages.append((t, c.pose_topic, "geometry_msgs/msg/PoseStamped", store.serialize_ros1(msg, "geometry_msgs/msg/PoseStamped")))

    Path(path).unlink(missing_ok=True)
    with Writer(Path(path)) as writer:
        connections = {}
        for t, topic, msgtype, raw in sorted(messages, key=lambda m: m[0]):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[topic], int(round(max(t, 0.0) * 1e9)), raw)
