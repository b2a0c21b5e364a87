"""Camera calibration files, one reader per format, each giving a CameraModel; shared by every
dataset plugin. Not a plugin.

    ECD calib.txt          fx fy cx cy [k1 k2 p1 p2 [k3]] (radtan; no sensor size)
    DV XML                 OpenCV FileStorage written by DV's calibration modules: the camera's
                           node (named after it) or the top level holds camera_matrix,
                           distortion_coefficients, image_width, image_height; the lens model is
                           `distortion_model` (RadialTangential / Equidistant) or, in older files,
                           `use_fisheye_model`, in the camera's node or at the top level
    kalibr camchain YAML   camN: camera_model pinhole, intrinsics [fu fv pu pv],
                           distortion_model radtan / equidistant, distortion_coeffs, resolution [w h]
    ROS camera_info YAML   image_width, image_height, camera_matrix, distortion_model
                           plumb_bob / equidistant, distortion_coefficients (camera_calibration_parsers)

`read_calibration` tells them apart by content. Every value is checked (sizes whole numbers of
pixels up to MAX_SENSOR_PX, everything finite, focal lengths, principal point and distortion in
range, the lens' projection growing out to the sensor's corners); every error is one line naming
the file and the key (or line) at fault.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from eas_vo.camera import LENS_MODELS, CameraModel
from eas_vo.errors import DataError
from eas_vo.io.tables import text_bytes

#: The largest sensor side [px] a calibration or a dataset may have (the largest event sensors
#: are a few thousand).
MAX_SENSOR_PX = 16384


def _intrinsics_problem(fx, fy, cx, cy, width: int, height: int) -> str | None:
    side = max(width, height)
    if not (0.1 * side <= fx <= 100 * side and 0.1 * side <= fy <= 100 * side):
        return (
            f"focal lengths fx = {fx:g}, fy = {fy:g} px are not those of a {width}x{height} camera "
            f"({0.1 * side:g} to {100 * side:g} px)"
        )
    if not (0 <= cx <= width and 0 <= cy <= height):
        return f"principal point cx = {cx:g}, cy = {cy:g} px lies off the {width}x{height} sensor"
    return None


def _distortion_problem(dist, model: str) -> str | None:
    dist = (list(dist) + [0.0] * len(LENS_MODELS[model]))[: len(LENS_MODELS[model])]
    if model == "equidistant":
        if not max(map(abs, dist)) <= 10:
            return f"distortion k1 k2 k3 k4 = {' '.join(f'{d:g}' for d in dist)} out of range (|k| <= 10)"
    elif not (max(abs(dist[0]), abs(dist[1]), abs(dist[4])) <= 10 and max(abs(dist[2]), abs(dist[3])) <= 1):
        return f"distortion k1 k2 p1 p2 k3 = {' '.join(f'{d:g}' for d in dist)} out of range (|k| <= 10, |p| <= 1)"
    return None


def _fold_problem(camera: CameraModel) -> str | None:
    """Where `camera`'s lens folds back inside its sensor (CameraModel.fold), as a message."""
    fold = camera.fold()
    if fold is None:
        return None
    radius_px, angle_rad, corner_px = fold
    names = " ".join(LENS_MODELS[camera.model])
    return (
        f"the {camera.model} lens ({names} = {' '.join(f'{d:g}' for d in camera.dist)}) folds back "
        f"{radius_px:.1f} px from the principal point ({angle_rad:.3f} rad off the optical axis), inside the "
        f"{camera.width}x{camera.height} sensor (its farthest corner {corner_px:.1f} px): a lens model must "
        "grow over the whole sensor"
    )


def camera_problem(values, width: int, height: int, model: str = "radtan") -> str | None:
    """What makes `fx fy cx cy` [px] and distortion coefficients (in `model`'s order) impossible
    for a width x height camera, or None: focal lengths between 0.1 and 100 sensor widths
    (fields of view of about 160 down to 0.6 degrees), the principal point on the sensor; radtan:
    |k1|, |k2|, |k3| <= 10 and |p1|, |p2| <= 1; equidistant: |k1..k4| <= 10; and the projection
    growing out to the sensor's corners (_fold_problem). NaN fails every range."""
    n = len(LENS_MODELS[model])
    dist = np.array((list(values[4:]) + [0.0] * n)[:n], float)
    return (
        _intrinsics_problem(*values[:4], width, height)
        or _distortion_problem(dist, model)
        or _fold_problem(CameraModel(width, height, _intrinsic_matrix(*values[:4]), dist, model))
    )


def sensor_size(where: str, value, key: str) -> tuple[int, int]:
    """(width, height) [px] from a calibration's two size values (ints, or floats holding whole
    numbers), each 1 to MAX_SENSOR_PX; else one DataError naming the file and `key`."""
    ok = len(value) == 2 and all(
        isinstance(v, (int, float, np.integer, np.floating))
        and not isinstance(v, bool)
        and math.isfinite(v)
        and v == int(v)
        and 1 <= v <= MAX_SENSOR_PX
        for v in value
    )
    if not ok:
        found = ", ".join(f"{v!r:.20}" for v in value)
        raise DataError(
            where, f"{key}: the sensor size must be two whole numbers of pixels, 1 to {MAX_SENSOR_PX} (found {found})"
        )
    return int(value[0]), int(value[1])


def check_frame_size(
    camera: CameraModel, width: int, height: int, where: str, what: str = "the frames are", key: str = ""
) -> None:
    """One DataError naming both sizes when images of width x height [px] (`what` they are: the
    frames, frame k, the recording's sensor) are not the size `camera` was calibrated for:
    its intrinsics describe another sensor (or a crop of one), whatever else fits."""
    if (camera.width, camera.height) != (width, height):
        at = f"{key}: " if key else ""
        raise DataError(where, f"{at}the calibration is for {camera.width}x{camera.height} px, {what} {width}x{height}")


def camera_model(
    where: str, width: int, height: int, K, dist, model: str = "radtan", keys: tuple[str, str, str] = ("", "", "")
) -> CameraModel:
    """A checked CameraModel from a 3x3 intrinsic matrix [px] and distortion coefficients in
    `model`'s order: radtan takes up to 5 (k1 k2 p1 p2 k3, those left out zero; more only if the
    extra rational terms are zero), equidistant exactly 4. `keys` name where the sensor size,
    the matrix and the coefficients came from in the file, for the messages."""
    K_key, dist_key = (f"{k}: " if k else "" for k in keys[1:])
    K, dist = np.asarray(K, float).ravel(), np.asarray(dist, float).ravel()
    width, height = sensor_size(where, (width, height), keys[0] or "sensor size")
    if len(K) != 9:
        raise DataError(where, f"{K_key}camera matrix has {len(K)} values, not 9")
    for at, values in ((K_key, K), (dist_key, dist)):
        if not np.isfinite(values).all():
            raise DataError(
                where, f"{at}intrinsics and distortion must be finite (found {' '.join(f'{v:g}' for v in values)})"
            )
    K = K.reshape(3, 3)
    n = len(LENS_MODELS[model])
    if model == "equidistant" and len(dist) != n:
        raise DataError(
            where,
            f"{dist_key}the equidistant lens model takes 4 distortion coefficients (k1 k2 k3 k4), found {len(dist)}",
        )
    if model == "radtan":
        if len(dist) > 5 and dist[5:].any():
            raise DataError(
                where,
                f"{dist_key}{len(dist)} radial-tangential distortion coefficients: k1 k2 p1 p2 [k3] are "
                "read (the rational and thin-prism terms of OpenCV's longer forms are not supported)",
            )
        dist = np.concatenate([dist, np.zeros(n)])[:n]
    if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise DataError(where, f"{K_key}camera matrix is not [[fx 0 cx] [0 fy cy] [0 0 1]] (skew is not supported)")
    for at, problem in (
        (K_key, _intrinsics_problem(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height)),
        (dist_key, _distortion_problem(dist, model)),
    ):
        if problem:
            raise DataError(where, f"{at}{problem}")
    camera = CameraModel(width, height, K, dist, model)
    problem = _fold_problem(camera)
    if problem:
        raise DataError(where, f"{dist_key}{problem}")
    return camera


def _intrinsic_matrix(fx, fy, cx, cy) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], float)


# -- ECD calib.txt ---------------------------------------------------------------------


def parse_ecd_calib(data: bytes, where: str, width: int, height: int) -> CameraModel:
    """The ECD `calib.txt` content (`fx fy cx cy [k1 k2 p1 p2 [k3]]`, radtan) for a width x height
    sensor; `#` lines are comments, as in every table."""
    lines = data.decode(errors="replace").splitlines()
    fields = [v for line in lines if not line.lstrip().startswith("#") for v in line.split()]
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
    image_height in a node named after the camera (e.g. `DVXplorer_DXA00093`), the lens model in
    `distortion_model` at the top level or (as cv2.FileStorage writes a camera's struct) in the
    camera's node; older ones keep them all at the top level, the lens model in
    `use_fisheye_model` (cv::fisheye, i.e. equidistant, when 1). `camera` picks the node when
    there are several. The lens: _dv_lens_model.
    """
    import cv2

    where = str(path)
    _read_bytes(path)  # a missing or unreadable file: our message, not OpenCV's
    try:
        fs = cv2.FileStorage(where, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # (OpenCV's parse errors surface as a SystemError over cv2.error)
        said = re.search(r"\((\d+)\): (.*?)'?$", str(exc.__cause__ or exc).strip())  # "...file.xml(2): <what>'"
        raise DataError(
            where,
            f"not a readable OpenCV XML file ({said[2] if said else 'unparsable'})",
            int(said[1]) if said else None,
        ) from None
    try:
        if not fs.isOpened():
            raise DataError(where, "not a readable OpenCV XML file")
        root = fs.root()
        nodes = {name: root.getNode(name) for name in root.keys()}
        cameras = [name for name, node in nodes.items() if node.isMap() and not node.getNode("camera_matrix").empty()]
        if camera is not None:
            if camera not in cameras:
                raise DataError(
                    where, f"no camera node {camera!r} (holding camera_matrix); found {', '.join(cameras) or 'none'}"
                )
            node, prefix = nodes[camera], f"{camera}/"
        elif not root.getNode("camera_matrix").empty():
            node, prefix = root, ""
        elif len(cameras) == 1:
            node, prefix = nodes[cameras[0]], f"{cameras[0]}/"
        elif cameras:
            raise DataError(
                where,
                f"holds {len(cameras)} cameras ({', '.join(cameras)}): choose one with camera=NAME "
                "(--set dataset.calibration_camera=NAME)",
            )
        else:
            raise DataError(
                where, "no camera_matrix, neither at the top level nor in a camera node: not a DV calibration"
            )
        K = _fs_matrix(where, node, prefix, "camera_matrix", 9)
        dist = _fs_matrix(where, node, prefix, "distortion_coefficients", None)
        width, height = (_fs_int(where, node, prefix, key) for key in ("image_width", "image_height"))
        model = _dv_lens_model(where, root, node, prefix, cameras)
    finally:
        fs.release()
    return camera_model(
        where,
        width,
        height,
        K,
        dist,
        model,
        (f"{prefix}image_width, image_height", f"{prefix}camera_matrix", f"{prefix}distortion_coefficients"),
    )


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


#: The keys that decide a DV calibration's lens model.
DV_LENS_KEYS = ("distortion_model", "use_fisheye_model")


def _dv_lens_model(where: str, root, node, prefix: str, cameras: list[str]) -> str:
    """The lens model of the camera in `node` (`root` in the older layout; `prefix` its path):
    `distortion_model` (a name) or `use_fisheye_model` (0 or 1), each read in the camera's node
    and at the top level. Both places holding a key must agree, and so must the two keys, except
    that use_fisheye_model 0 says nothing beside a distortion_model (DV's camera calibration
    writes 0 whatever the model). A lens key anywhere else is an error, never ignored."""
    _no_lens_keys_elsewhere(where, root, "", set(cameras))
    names, flags = {}, {}
    for at, place in [(prefix, node)] + ([("", root)] if prefix else []):
        named, flag = place.getNode("distortion_model"), place.getNode("use_fisheye_model")
        if not named.empty():
            name = named.string() if named.isString() else ""
            if name.lower() not in DV_LENS_MODELS:
                raise DataError(
                    where,
                    f"{at}distortion_model: {name or 'not a name'!r} is not read (RadialTangential or Equidistant)",
                )
            names[f"{at}distortion_model"] = DV_LENS_MODELS[name.lower()]
        if not flag.empty():
            if not (flag.isInt() and flag.real() in (0, 1)):
                raise DataError(where, f"{at}use_fisheye_model: expected 0 or 1")
            flags[f"{at}use_fisheye_model"] = "equidistant" if flag.real() else "radtan"
    for said in (names, flags):
        if len(set(said.values())) > 1:
            raise DataError(where, "; ".join(f"{key} says {model}" for key, model in said.items()) + ": which lens?")
    fisheye = [key for key, model in flags.items() if model == "equidistant"]
    if names:
        key, model = next(iter(names.items()))
        if fisheye and model != "equidistant":
            raise DataError(where, f"{key} says {model}; {fisheye[0]} says equidistant (a fisheye): which lens?")
        return model
    return "equidistant" if fisheye else "radtan"


def _no_lens_keys_elsewhere(where: str, node, path: str, cameras: set[str]) -> None:
    """A DataError for a lens key (DV_LENS_KEYS) at any depth of `node` but the top level and
    the camera nodes (`cameras`), where _dv_lens_model reads them."""
    if node.isMap():
        for key in node.keys():
            at = f"{path}{key}"
            if key in DV_LENS_KEYS and path and path[:-1] not in cameras:
                raise DataError(
                    where,
                    f"{at}: a lens model key where it is not read (it is read at the top level and in a camera's node)",
                )
            _no_lens_keys_elsewhere(where, node.getNode(key), f"{at}/", cameras)
    elif node.isSeq():
        for k in range(node.size()):
            _no_lens_keys_elsewhere(where, node.at(k), f"{path}{k}/", cameras)


# -- YAML: kalibr camchain and ROS camera_info ----------------------------------------------


#: kalibr's and ROS's distortion model names -> lens models.
YAML_LENS_MODELS = {
    "radtan": "radtan",
    "plumb_bob": "radtan",
    "rational_polynomial": "radtan",
    "equidistant": "equidistant",
    "none": "radtan",
}


def _load_yaml(path: str | Path) -> dict:
    return _parse_yaml(_read_bytes(path), str(path))


def _parse_yaml(data: bytes, where: str) -> dict:
    import yaml

    try:
        content = yaml.safe_load(data)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise DataError(
            where, f"not valid YAML ({getattr(exc, 'problem', None) or exc})", None if mark is None else mark.line + 1
        ) from None
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
        raise DataError(
            where,
            f"no camera {camera!r}; found {found}"
            if found
            else "not a calibration read here: no camN of a kalibr camchain, nor the image_width and "
            "camera_matrix of a ROS camera_info",
        )
    if cam.get("camera_model") != "pinhole":
        raise DataError(where, f"{camera}.camera_model: {cam.get('camera_model')!r} is not read (pinhole only)")
    fu, fv, pu, pv = _numbers(where, cam, "intrinsics", 4, f"{camera}.intrinsics")
    width, height = sensor_size(
        where, _numbers(where, cam, "resolution", 2, f"{camera}.resolution"), f"{camera}.resolution"
    )
    model = _lens(where, cam, "distortion_model")
    dist = _numbers(where, cam, "distortion_coeffs", None, f"{camera}.distortion_coeffs")
    if cam["distortion_model"] == "none" and any(dist):
        raise DataError(where, f"{camera}.distortion_coeffs: distortion_model none with non-zero coefficients")
    return camera_model(
        where,
        width,
        height,
        _intrinsic_matrix(fu, fv, pu, pv),
        dist,
        model,
        (f"{camera}.resolution", f"{camera}.intrinsics", f"{camera}.distortion_coeffs"),
    )


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
            raise DataError(
                where,
                f"{key}: expected a matrix (rows, cols, data), found {'missing' if table is None else repr(table)}",
            )
        matrices[key] = _numbers(where, table, "data", 9 if key == "camera_matrix" else None, f"{key}.data")
    return camera_from_camera_info(
        where,
        size[0],
        size[1],
        matrices["camera_matrix"],
        matrices["distortion_coefficients"],
        content.get("distortion_model"),
        "camera_matrix/distortion_coefficients",
        "image_width, image_height",
    )


def camera_from_camera_info(
    where: str, width: int, height: int, K, D, distortion_model, key: str = "K/D", size_key: str = "width, height"
) -> CameraModel:
    """sensor_msgs/CameraInfo fields (a message or its YAML) -> CameraModel: K row-major [px], D in
    the order of `distortion_model` (plumb_bob, rational_polynomial with k4..k6 zero, or
    equidistant; an empty name, as old drivers leave it, is plumb_bob). `key` names the K and D
    fields together (`K/D`), `size_key` the size's, for the messages."""
    if distortion_model == "":
        distortion_model = "plumb_bob"
    model = _lens(where, {"distortion_model": distortion_model}, "distortion_model")
    return camera_model(where, width, height, K, D, model, (size_key, key, key))


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


def read_calibration(
    path: str | Path, *, width: int | None = None, height: int | None = None, camera: str | None = None
) -> CameraModel:
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
    if width is not None and height is not None:
        check_frame_size(model, width, height, where, "the recording's sensor is", size_keys)
    return model


def _read_bytes(path: str | Path) -> bytes:
    try:
        return text_bytes(Path(path).read_bytes())
    except OSError as exc:
        raise DataError(str(path), f"cannot read the calibration: {exc.strerror or exc}") from None
