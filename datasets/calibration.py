"""Camera calibration files, one reader per format, each giving a CameraModel; shared by every
dataset plugin. Not a plugin.

    ECD calib.txt          fx fy cx cy [k1 k2 p1 p2 [k3]] (radtan; no sensor size)
    DV XML                 OpenCV FileStorage written by DV's calibration modules: the camera's
                           node (named after it) or the top level holds camera_matrix,
                           distortion_coefficients, image_width, image_height; the lens model is
                           `distortion_model` (RadialTangential / Equidistant) or, in older files,
                           `use_fisheye_model`
    kalibr camchain YAML   camN: camera_model pinhole, intrinsics [fu fv pu pv],
                           distortion_model radtan / equidistant, distortion_coeffs, resolution [w h]
    ROS camera_info YAML   image_width, image_height, camera_matrix, distortion_model
                           plumb_bob / equidistant, distortion_coefficients (camera_calibration_parsers)

`read_calibration` tells them apart by content. Every error is one line naming the file and
the key (or line) at fault.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError
from eas_vo.types import LENS_MODELS, CameraModel


def camera_problem(values, width: int, height: int, model: str = "radtan") -> str | None:
    """What makes `fx fy cx cy` [px] and distortion coefficients (in `model`'s order) impossible
    for a width x height camera, or None: focal lengths between 0.1 and 100 sensor widths
    (fields of view of about 160 down to 0.6 degrees), the principal point on the sensor; radtan:
    |k1|, |k2|, |k3| <= 10 and |p1|, |p2| <= 1; equidistant: |k1..k4| <= 10 (beyond, the model no
    longer maps the sensor)."""
    fx, fy, cx, cy = values[:4]
    side = max(width, height)
    if not (0.1 * side <= fx <= 100 * side and 0.1 * side <= fy <= 100 * side):
        return f"focal lengths fx = {fx:g}, fy = {fy:g} px are not those of a {width}x{height} camera " \
               f"({0.1 * side:g} to {100 * side:g} px)"
    if not (0 <= cx <= width and 0 <= cy <= height):
        return f"principal point cx = {cx:g}, cy = {cy:g} px lies off the {width}x{height} sensor"
    dist = (list(values[4:]) + [0.0] * len(LENS_MODELS[model]))[: len(LENS_MODELS[model])]
    if model == "equidistant":
        if max(map(abs, dist)) > 10:
            return f"distortion k1 k2 k3 k4 = {' '.join(f'{d:g}' for d in dist)} out of range (|k| <= 10)"
    elif max(abs(dist[0]), abs(dist[1]), abs(dist[4])) > 10 or max(abs(dist[2]), abs(dist[3])) > 1:
        return f"distortion k1 k2 p1 p2 k3 = {' '.join(f'{d:g}' for d in dist)} out of range (|k| <= 10, |p| <= 1)"
    return None


def camera_model(where: str, width: int, height: int, K, dist, model: str = "radtan", key: str = "") -> CameraModel:
    """A checked CameraModel from a 3x3 intrinsic matrix [px] and distortion coefficients in
    `model`'s order: radtan takes up to 5 (k1 k2 p1 p2 k3, those left out zero; more only if the
    extra rational terms are zero), equidistant exactly 4. `key` names where they came from in the file."""
    at = f"{key}: " if key else ""
    K, dist = np.asarray(K, float).ravel(), np.asarray(dist, float).ravel()
    if len(K) != 9:
        raise DataError(where, f"{at}camera matrix has {len(K)} values, not 9")
    K = K.reshape(3, 3)
    if not (1 <= width <= 1 << 16 and 1 <= height <= 1 << 16):
        raise DataError(where, f"{at}sensor size {width}x{height} px is not a camera's")
    if not (np.isfinite(K).all() and np.isfinite(dist).all()):
        raise DataError(where, f"{at}intrinsics and distortion must be finite (found NaN or infinity)")
    n = len(LENS_MODELS[model])
    if model == "equidistant" and len(dist) != n:
        raise DataError(where, f"{at}the equidistant lens model takes 4 distortion coefficients (k1 k2 k3 k4), found {len(dist)}")
    if model == "radtan":
        if len(dist) > 5 and dist[5:].any():
            raise DataError(where, f"{at}{len(dist)} radial-tangential distortion coefficients: k1 k2 p1 p2 [k3] are read "
                                   "(the rational and thin-prism terms of OpenCV's longer forms are not supported)")
        dist = np.concatenate([dist, np.zeros(n)])[:n]
    if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise DataError(where, f"{at}camera matrix is not [[fx 0 cx] [0 fy cy] [0 0 1]] (skew is not supported)")
    values = [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist]
    problem = camera_problem(values, width, height, model)
    if problem:
        raise DataError(where, f"{at}{problem}")
    return CameraModel(int(width), int(height), K, dist, model)


def _intrinsic_matrix(fx, fy, cx, cy) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], float)


# -- ECD calib.txt ---------------------------------------------------------------------


def parse_ecd_calib(data: bytes, where: str, width: int, height: int) -> CameraModel:
    """The ECD `calib.txt` content (`fx fy cx cy [k1 k2 p1 p2 [k3]]`, radtan) for a width x height sensor."""
    fields = data.decode(errors="replace").split()
    try:
        values = [float(v) for v in fields]
    except ValueError:
        raise DataError(where, "calibration values must be numbers", 1) from None
    if len(values) not in (4, 8, 9):
        raise DataError(where, f"expected 4, 8 or 9 values (fx fy cx cy k1 k2 p1 p2 k3), found {len(values)}", 1)
    if not all(map(math.isfinite, values)):
        raise DataError(where, "calibration values must be finite (found NaN or infinity)", 1)
    problem = camera_problem(values, width, height)
    if problem:
        raise DataError(where, problem, 1)
    return CameraModel.from_calib(values, width, height)


def read_ecd_calib(path: str | Path, width: int, height: int) -> CameraModel:
    """An ECD `calib.txt` for a width x height sensor (the file does not give it)."""
    return parse_ecd_calib(_read_bytes(path), str(path), width, height)


# -- DV's calibration XML -------------------------------------------------------------


#: DV's `distortion_model` names -> lens models.
DV_LENS_MODELS = {"radialtangential": "radtan", "equidistant": "equidistant"}


def read_dv_xml(path: str | Path, camera: str | None = None) -> CameraModel:
    """A calibration XML written by DV's camera calibration (OpenCV FileStorage, which reads its
    YAML form too).

    Newer files keep each camera's camera_matrix, distortion_coefficients, image_width and
    image_height in a node named after the camera (e.g. `DVXplorer_DXA00093`) and the lens model
    in the top-level `distortion_model`; older ones keep them all at the top level, the lens
    model in `use_fisheye_model` (cv::fisheye, i.e. equidistant, when 1). `camera` picks the
    node when there are several.
    """
    import cv2

    where = str(path)
    _read_bytes(path)  # a missing or unreadable file: our message, not OpenCV's
    try:
        fs = cv2.FileStorage(where, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # (OpenCV's parse errors surface as a SystemError over cv2.error)
        said = re.search(r"\((\d+)\): (.*?)'?$", str(exc.__cause__ or exc).strip())  # "...file.xml(2): <what>'"
        raise DataError(where, f"not a readable OpenCV XML file ({said[2] if said else 'unparsable'})",
                        int(said[1]) if said else None) from None
    try:
        if not fs.isOpened():
            raise DataError(where, "not a readable OpenCV XML file")
        root = fs.root()
        nodes = {name: root.getNode(name) for name in root.keys()}
        cameras = [name for name, node in nodes.items() if node.isMap() and not node.getNode("camera_matrix").empty()]
        if camera is not None:
            if camera not in cameras:
                raise DataError(where, f"no camera node {camera!r} (holding camera_matrix); found {', '.join(cameras) or 'none'}")
            node, prefix = nodes[camera], f"{camera}/"
        elif not root.getNode("camera_matrix").empty():
            node, prefix = root, ""
        elif len(cameras) == 1:
            node, prefix = nodes[cameras[0]], f"{cameras[0]}/"
        elif cameras:
            raise DataError(where, f"holds {len(cameras)} cameras ({', '.join(cameras)}): choose one with camera=NAME "
                                   "(--set dataset.camera=NAME)")
        else:
            raise DataError(where, "no camera_matrix, neither at the top level nor in a camera node: not a DV calibration")
        K = _fs_matrix(where, node, prefix, "camera_matrix", 9)
        dist = _fs_matrix(where, node, prefix, "distortion_coefficients", None)
        width, height = (_fs_int(where, node, prefix, key) for key in ("image_width", "image_height"))
        model = _dv_lens_model(where, root)
    finally:
        fs.release()
    return camera_model(where, width, height, K, dist, model, f"{prefix}camera_matrix/distortion_coefficients")


def _fs_matrix(where: str, node, prefix: str, key: str, size: int | None) -> np.ndarray:
    import cv2

    value = node.getNode(key)
    try:
        matrix = None if value.empty() else value.mat()
    except cv2.error:  # rows x cols not the number of values
        matrix = None
    if matrix is None:
        raise DataError(where, f"{prefix}{key}: missing, or not an opencv-matrix (rows, cols, dt, data)")
    if size is not None and matrix.size != size:
        raise DataError(where, f"{prefix}{key}: {matrix.size} values, expected {size}")
    return np.asarray(matrix, float).ravel()


def _fs_int(where: str, node, prefix: str, key: str) -> int:
    value = node.getNode(key)
    if value.empty() or not value.isInt():
        raise DataError(where, f"{prefix}{key}: missing, or not an integer")
    return int(value.real())


def _dv_lens_model(where: str, root) -> str:
    named = root.getNode("distortion_model")
    if not named.empty():
        name = named.string() if named.isString() else ""
        if name.lower() not in DV_LENS_MODELS:
            raise DataError(where, f"distortion_model: {name or 'not a name'!r} is not read (RadialTangential or Equidistant)")
        return DV_LENS_MODELS[name.lower()]
    fisheye = root.getNode("use_fisheye_model")
    return "equidistant" if not fisheye.empty() and fisheye.isInt() and fisheye.real() != 0 else "radtan"


# -- YAML: kalibr camchain and ROS camera_info ----------------------------------------------


#: kalibr's and ROS's distortion model names -> lens models.
YAML_LENS_MODELS = {"radtan": "radtan", "plumb_bob": "radtan", "rational_polynomial": "radtan", "equidistant": "equidistant",
                    "none": "radtan"}


def _load_yaml(path: str | Path) -> dict:
    return _parse_yaml(_read_bytes(path), str(path))


def _parse_yaml(data: bytes, where: str) -> dict:
    import yaml

    try:
        content = yaml.safe_load(data)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise DataError(where, f"not valid YAML ({getattr(exc, 'problem', None) or exc})",
                        None if mark is None else mark.line + 1) from None
    if not isinstance(content, dict):
        raise DataError(where, "not a YAML mapping of calibration keys")
    return content


def _numbers(where: str, table: dict, key: str, count: int | None, name: str = "") -> list[float]:
    value = table.get(key)
    ok = isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    if not ok or (count is not None and len(value) != count):
        want = f"a list of {count} numbers" if count is not None else "a list of numbers"
        found = "missing" if value is None else f"{value!r:.60}"
        raise DataError(where, f"{name or key}: expected {want}, found {found}")
    return [float(v) for v in value]


def _lens(where: str, table: dict, key: str) -> str:
    name = table.get(key)
    if not isinstance(name, str) or name.lower() not in YAML_LENS_MODELS:
        raise DataError(where, f"{key}: {name!r} is not read (one of {', '.join(YAML_LENS_MODELS)})")
    return YAML_LENS_MODELS[name.lower()]


def read_kalibr_camchain(path: str | Path, camera: str = "cam0") -> CameraModel:
    """Camera `camera` (cam0, cam1, ...) of a kalibr camchain YAML (pinhole cameras only)."""
    return parse_kalibr_camchain(_read_bytes(path), str(path), camera)


def parse_kalibr_camchain(data: bytes, where: str, camera: str = "cam0") -> CameraModel:
    """Camera `camera` of the kalibr camchain YAML `data` (read from `where`, for messages)."""
    content = _parse_yaml(data, where)
    cam = content.get(camera)
    if not isinstance(cam, dict):
        found = ", ".join(k for k, v in content.items() if isinstance(v, dict) and "intrinsics" in v)
        raise DataError(where, f"no camera {camera!r}; found {found}" if found else
                        "not a calibration read here: no camN of a kalibr camchain, nor the image_width and "
                        "camera_matrix of a ROS camera_info")
    if cam.get("camera_model") != "pinhole":
        raise DataError(where, f"{camera}.camera_model: {cam.get('camera_model')!r} is not read (pinhole only)")
    fu, fv, pu, pv = _numbers(where, cam, "intrinsics", 4, f"{camera}.intrinsics")
    width, height = _numbers(where, cam, "resolution", 2, f"{camera}.resolution")
    model = _lens(where, cam, "distortion_model")
    dist = _numbers(where, cam, "distortion_coeffs", None, f"{camera}.distortion_coeffs")
    if cam["distortion_model"] == "none" and any(dist):
        raise DataError(where, f"{camera}.distortion_coeffs: distortion_model none with non-zero coefficients")
    return camera_model(where, int(width), int(height), _intrinsic_matrix(fu, fv, pu, pv), dist, model,
                        f"{camera}.distortion_coeffs")


def read_camera_info_yaml(path: str | Path) -> CameraModel:
    """A ROS camera_info YAML (camera_calibration_parsers' layout; the rectification and
    projection matrices, for stereo rectification, are not read)."""
    where = str(path)
    content = _load_yaml(path)
    size = []
    for key in ("image_width", "image_height"):
        value = content.get(key)
        if not isinstance(value, int) or isinstance(value, bool):
            raise DataError(where, f"{key}: expected an integer, found {'missing' if value is None else repr(value)}")
        size.append(value)
    matrices = {}
    for key in ("camera_matrix", "distortion_coefficients"):
        table = content.get(key)
        if not isinstance(table, dict):
            raise DataError(where, f"{key}: expected a matrix (rows, cols, data), found {'missing' if table is None else repr(table)}")
        matrices[key] = _numbers(where, table, "data", 9 if key == "camera_matrix" else None, f"{key}.data")
    return camera_from_camera_info(where, size[0], size[1], matrices["camera_matrix"], matrices["distortion_coefficients"],
                                   content.get("distortion_model"), "camera_matrix/distortion_coefficients")


def camera_from_camera_info(where: str, width: int, height: int, K, D, distortion_model, key: str = "K/D") -> CameraModel:
    """sensor_msgs/CameraInfo fields (a message or its YAML) -> CameraModel: K row-major [px], D in
    the order of `distortion_model` (plumb_bob, rational_polynomial with k4..k6 zero, or
    equidistant; an empty name, as old drivers leave it, is plumb_bob)."""
    if distortion_model == "":
        distortion_model = "plumb_bob"
    model = _lens(where, {"distortion_model": distortion_model}, "distortion_model")
    return camera_model(where, width, height, K, D, model, key)


# -- any of them -------------------------------------------------------------------------


def calibration_format(path: str | Path) -> str:
    """`dv_xml`, `kalibr`, `camera_info` or `ecd` from a look at the content of `path`."""
    head = _read_bytes(path)[:4096].lstrip()
    if head.startswith((b"<?xml", b"<opencv_storage")) or (head.startswith(b"%YAML") and b"opencv-matrix" in head):
        return "dv_xml"  # (DV writes XML; OpenCV's YAML form of the same content is read alike)
    text = head.decode(errors="replace")
    first = text.split()[0] if text.split() else ""
    try:
        float(first)
        return "ecd"
    except ValueError:
        pass
    if "image_width" in text and "camera_matrix" in text:
        return "camera_info"
    return "kalibr"


def read_calibration(path: str | Path, *, width: int | None = None, height: int | None = None,
                     camera: str | None = None) -> CameraModel:
    """The calibration in `path`, whatever of the four formats it is in (told by content).

    width, height: the recording's sensor size [px]: required for an ECD calib.txt (which does
    not give it); for the others, a calibration of another size is refused.
    camera: the camera to read (a kalibr `camN`, default cam0; a DV XML camera node).
    """
    fmt = calibration_format(path)
    where = str(path)
    if fmt == "ecd":
        if width is None or height is None:
            raise DataError(where, "an ECD calib.txt gives no sensor size; the dataset must supply it")
        return read_ecd_calib(path, width, height)
    if fmt == "dv_xml":
        model, size_keys = read_dv_xml(path, camera), "image_width, image_height"
    elif fmt == "camera_info":
        model, size_keys = read_camera_info_yaml(path), "image_width, image_height"
    else:
        model, size_keys = read_kalibr_camchain(path, camera or "cam0"), f"{camera or 'cam0'}.resolution"
    if width is not None and height is not None and (model.width, model.height) != (width, height):
        raise DataError(where, f"{size_keys}: the calibration is for {model.width}x{model.height} px, "
                               f"the recording's sensor is {width}x{height}")
    return model


def _read_bytes(path: str | Path) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise DataError(str(path), f"cannot read the calibration: {exc.strerror or exc}") from None
