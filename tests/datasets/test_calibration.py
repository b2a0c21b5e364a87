"""Calibration readers: files written as DV, kalibr, ROS and the ECD write them, read back exactly;
one-line errors naming the file and the key."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from eas_vo.camera import LENS_MODELS, CameraModel
from eas_vo.datasets.calibration import (
    calibration_format,
    read_calibration,
    read_dv_xml,
    read_kalibr_camchain,
)
from eas_vo.errors import DataError
from helpers import ECD_DAVIS240, MVSEC_LEFT, K_of, write_dv_xml

# A DAVIS346 with a fisheye lens (values of the size MVSEC's kalibr calibrations have) and one
# with radial-tangential distortion.
FISHEYE = dict(
    width=346,
    height=260,
    f=(226.380185, 226.150029),
    c=(173.647081, 133.732715),
    dist=[-0.048031, 0.011331, -0.055378, 0.021501],
    model="equidistant",
)
RADTAN = dict(
    width=346,
    height=260,
    f=(259.351, 259.164),
    c=(176.201, 131.517),
    dist=[-0.3605, 0.1532, 0.00021, -0.00047, -0.0311],
    model="radtan",
)


def assert_camera(model, cam) -> None:
    assert (model.width, model.height, model.model) == (cam["width"], cam["height"], cam["model"])
    np.testing.assert_array_equal(model.K, K_of(cam))
    np.testing.assert_array_equal(model.dist, cam["dist"])


# -- writers, as each tool writes its file ---------------------------------------------------


def write_dv_legacy_xml(path, cam):
    """As DV's older lens calibration module writes it: everything at the top level."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("calibration_time", "Tue Dec  1 10:00:00 2026")
    fs.write("nr_of_frames", 30)
    fs.write("image_width", cam["width"])
    fs.write("image_height", cam["height"])
    fs.write("board_width", 9)
    fs.write("board_height", 5)
    fs.write("square_size", 30.0)
    fs.write("flags", 0)
    fs.write("use_fisheye_model", int(cam["model"] == "equidistant"))
    fs.write("camera_matrix", K_of(cam))
    fs.write("distortion_coefficients", np.array(cam["dist"]).reshape(-1, 1))
    fs.write("avg_reprojection_error", 0.21)
    fs.release()


def write_kalibr(path, cam, second=None):
    """A camchain as kalibr writes it (yaml.dump of its dictionary, flow-style lists)."""

    def block(name, c, extra):
        (fx, fy), (cx, cy) = c["f"], c["c"]
        return (
            f"{name}:\n{extra}  cam_overlaps: []\n  camera_model: pinhole\n"
            f"  distortion_coeffs: [{', '.join(repr(d) for d in c['dist'])}]\n"
            f"  distortion_model: {'equidistant' if c['model'] == 'equidistant' else 'radtan'}\n"
            f"  intrinsics: [{fx!r}, {fy!r}, {cx!r}, {cy!r}]\n"
            f"  resolution: [{c['width']}, {c['height']}]\n  rostopic: /davis/{name}/image_raw\n"
        )

    text = block(
        "cam0",
        cam,
        "  T_cam_imu:\n  - [1.0, 0.0, 0.0, 0.0]\n  - [0.0, 1.0, 0.0, 0.0]\n"
        "  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n",
    )
    if second is not None:
        text += block(
            "cam1",
            second,
            "  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, -0.1]\n  - [0.0, 1.0, 0.0, 0.0]\n"
            "  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n",
        )
    path.write_text(text)


def write_camera_info(path, cam):
    """As ROS's camera_calibration_parsers write it."""
    (fx, fy), (cx, cy) = cam["f"], cam["c"]
    dist = ", ".join(repr(d) for d in cam["dist"])
    path.write_text(
        f"image_width: {cam['width']}\nimage_height: {cam['height']}\ncamera_name: davis\n"
        f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{fx!r}, 0, {cx!r}, 0, {fy!r}, {cy!r}, 0, 0, 1]\n"
        f"distortion_model: {'equidistant' if cam['model'] == 'equidistant' else 'plumb_bob'}\n"
        f"distortion_coefficients:\n  rows: 1\n  cols: {len(cam['dist'])}\n  data: [{dist}]\n"
        "rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
        f"projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{fx!r}, 0, {cx!r}, 0, 0, {fy!r}, {cy!r}, 0, 0, 0, 1, 0]\n"
    )


def write_ecd(path, cam):
    (fx, fy), (cx, cy) = cam["f"], cam["c"]
    path.write_text(" ".join(repr(v) for v in (fx, fy, cx, cy, *cam["dist"])) + "\n")


WRITERS = {
    "dv_xml": write_dv_xml,
    "dv_legacy_xml": write_dv_legacy_xml,
    "kalibr": write_kalibr,
    "camera_info": write_camera_info,
    "ecd": write_ecd,
}
#: The names the tools give their files (OpenCV's FileStorage picks XML from the suffix).
NAMES = {
    "dv_xml": "calibration_camera_DAVIS346.xml",
    "dv_legacy_xml": "calibration.xml",
    "kalibr": "camchain.yaml",
    "camera_info": "davis.yaml",
    "ecd": "calib.txt",
}


# -- known answers ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "fmt, cam",
    [
        (fmt, cam) for fmt in WRITERS for cam in (FISHEYE, RADTAN) if fmt != "ecd" or cam is RADTAN
    ],  # an ECD calib.txt is radtan only
    ids=lambda v: v if isinstance(v, str) else v["model"],
)
def test_each_format_reads_back_exactly(tmp_path, fmt, cam):
    path = tmp_path / NAMES[fmt]
    WRITERS[fmt](path, cam)
    assert calibration_format(path) == fmt.replace("dv_legacy_xml", "dv_xml")
    assert_camera(read_calibration(path, width=cam["width"], height=cam["height"]), cam)


def test_the_format_readers_agree_on_undistortion(tmp_path):
    """One radtan camera in four files: the same undistorted points, equal to OpenCV's from the
    values written."""
    pts = np.array([[0.0, 0.0], [345.0, 259.0], [173.0, 130.0], [10.5, 250.25]])
    expected = cv2.undistortPoints(pts.reshape(-1, 1, 2), K_of(RADTAN), np.array(RADTAN["dist"])).reshape(-1, 2)
    for fmt in ("dv_xml", "kalibr", "camera_info", "ecd"):
        path = tmp_path / NAMES[fmt]
        WRITERS[fmt](path, RADTAN)
        np.testing.assert_array_equal(read_calibration(path, width=346, height=260).undistort(pts), expected)


def test_dv_xml_agrees_with_dv_processing(tmp_path):
    """dv-processing's own reader of DV's calibration files gives the same intrinsics."""
    dv = pytest.importorskip("dv_processing", reason="dv-processing (the test extra's peer) is not installed")
    path = tmp_path / "calibration.xml"
    write_dv_xml(path, RADTAN)
    peer = dv.camera.CalibrationSet.LoadFromFile(str(path)).getCameraCalibrationByName("DAVIS346_00000499")
    ours = read_dv_xml(path)
    np.testing.assert_allclose(ours.K, np.asarray(peer.getCameraMatrix(), float), rtol=1e-6)
    np.testing.assert_allclose(ours.dist, np.asarray(peer.distortion, float), rtol=1e-6)
    assert (ours.width, ours.height) == tuple(peer.resolution)


def test_kalibr_picks_the_camera(tmp_path):
    path = tmp_path / "camchain.yaml"
    write_kalibr(path, FISHEYE, second=RADTAN)
    assert_camera(read_kalibr_camchain(path), FISHEYE)
    assert_camera(read_calibration(path, camera="cam1"), RADTAN)
    with pytest.raises(DataError, match=r"camchain.yaml: no camera 'cam2'; found cam0, cam1$"):
        read_kalibr_camchain(path, "cam2")


def test_dv_xml_with_two_cameras_needs_a_choice(tmp_path):
    path = tmp_path / "stereo.xml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for node in ("DAVIS346_left", "DAVIS346_right"):
        fs.startWriteStruct(node, cv2.FILE_NODE_MAP)
        fs.write("camera_matrix", K_of(RADTAN))
        fs.write("distortion_coefficients", np.array([RADTAN["dist"]]))
        fs.write("image_width", 346)
        fs.write("image_height", 260)
        fs.endWriteStruct()
    fs.release()
    with pytest.raises(DataError, match=r"stereo.xml: holds 2 cameras \(DAVIS346_left, DAVIS346_right\): choose one"):
        read_dv_xml(path)
    assert_camera(read_calibration(path, camera="DAVIS346_right"), RADTAN)


# -- errors ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "fmt, damage, message",
    [
        (
            "kalibr",
            lambda t: t.replace("  intrinsics: [", "  intrinsics: [1.0, "),
            r"cam0.intrinsics: expected a list of 4 numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("camera_model: pinhole", "camera_model: omni"),
            r"cam0.camera_model: 'omni' is not read",
        ),
        (
            "kalibr",
            lambda t: t.replace("distortion_model: radtan", "distortion_model: fov"),
            r"distortion_model: 'fov' is not read",
        ),
        (
            "kalibr",
            lambda t: t.replace("resolution: [346, 260]", "resolution: [346]"),
            r"cam0.resolution: expected a list of 2",
        ),
        ("kalibr", lambda t: t.replace("cam0:", "cam0: [").replace("rostopic", "]"), r"not valid YAML"),
        (
            "camera_info",
            lambda t: t.replace("image_height: 260\n", ""),
            r"image_height: expected an integer, found missing",
        ),
        ("camera_info", lambda t: t.replace("plumb_bob", "fov"), r"'fov' is not read"),
        ("camera_info", lambda t: t.replace("data: [259.351, 0,", "data: [0.001, 0,"), r"focal lengths fx = 0.001"),
        (
            "camera_info",
            lambda t: t.replace("-0.0311]", "-0.0311, 0.5, 0, 0]"),
            r"8 radial-tangential distortion coefficients",
        ),
        (
            "dv_xml",
            lambda t: t.replace("<image_width>346</image_width>", ""),
            r"DAVIS346_00000499/image_width: missing",
        ),
        ("dv_xml", lambda t: t.replace("RadialTangential", "FOV"), r"distortion_model: 'FOV' is not read"),
        (
            "dv_xml",
            lambda t: (
                t.replace("<rows>3</rows>", "<rows>1</rows>", 1)
                .replace("<cols>3</cols>", "<cols>2</cols>", 1)
                .replace("2.5935100000000000e+02 0.", "2.5935100000000000e+02 ")
            ),
            r"camera_matrix: ",
        ),
        ("ecd", lambda t: "200 200 120\n", r"calib.txt:1: expected 4, 8 or 9 values"),
    ],
)
def test_errors_name_the_file_and_key(tmp_path, fmt, damage, message):
    path = tmp_path / NAMES[fmt]
    WRITERS[fmt](path, RADTAN)
    path.write_text(damage(path.read_text()))
    with pytest.raises(DataError, match=message) as info:
        read_calibration(path, width=346, height=260)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_a_calibration_of_another_size_is_refused(tmp_path):
    path = tmp_path / "camchain.yaml"
    write_kalibr(path, RADTAN)
    with pytest.raises(
        DataError, match=r"cam0.resolution: the calibration is for 346x260 px, the recording's sensor is 640x480"
    ):
        read_calibration(path, width=640, height=480)


def test_an_ecd_calibration_needs_the_sensor_size(tmp_path):
    path = tmp_path / "calib.txt"
    write_ecd(path, RADTAN)
    with pytest.raises(DataError, match=r"calib.txt: an ECD calib.txt gives no sensor size"):
        read_calibration(path)


def test_missing_and_foreign_files(tmp_path):
    with pytest.raises(DataError, match=r"absent.yaml: cannot read the calibration"):
        read_calibration(tmp_path / "absent.yaml")
    text = tmp_path / "notes.xml"
    text.write_text("<?xml version='1.0'?>\n<notes>a renamed text file</notes>\n")
    with pytest.raises(
        DataError, match=r"notes.xml:2: not a readable OpenCV XML file \(<opencv_storage> tag is missing\)"
    ):
        read_calibration(text)


@pytest.mark.parametrize("fmt", ["dv_xml", "dv_legacy_xml", "kalibr", "camera_info"])
def test_truncated_files_are_named_errors_or_the_whole_calibration(tmp_path, fmt):
    """Cut at any byte: a one-line error naming the file, or (cut in what is not read) exactly
    the calibration of the whole file."""
    from hypothesis import given
    from hypothesis import strategies as st

    from helpers import hostile_settings

    whole = tmp_path / NAMES[fmt]
    WRITERS[fmt](whole, FISHEYE)
    data = whole.read_bytes()
    cut = tmp_path / ("cut_" + NAMES[fmt])

    @hostile_settings(60)
    @given(st.integers(0, len(data) - 1))
    def check(offset):
        cut.write_bytes(data[:offset])
        try:
            model = read_calibration(cut)
        except DataError as exc:
            assert str(exc).startswith(str(cut)) and "\n" not in str(exc)
            return
        assert_camera(model, FISHEYE)

    check()


def test_camera_info_fields_as_a_bag_gives_them():
    """The sensor_msgs/CameraInfo fields a ROS bag's message holds: the lens model follows
    distortion_model (an empty one, as old drivers leave it, is plumb_bob)."""
    from eas_vo.datasets.calibration import camera_from_camera_info

    K = K_of(FISHEYE).ravel()
    assert_camera(
        camera_from_camera_info("x.bag:/dvs/camera_info:0", 346, 260, K, FISHEYE["dist"], "equidistant"), FISHEYE
    )
    radtan = camera_from_camera_info("x.bag:/dvs/camera_info:0", 346, 260, K_of(RADTAN).ravel(), RADTAN["dist"], "")
    assert_camera(radtan, RADTAN)
    with pytest.raises(DataError, match=r"^x.bag:/dvs/camera_info:0: K/D: the equidistant lens model takes 4"):
        camera_from_camera_info("x.bag:/dvs/camera_info:0", 346, 260, K, RADTAN["dist"], "equidistant")


# -- the lens model of a DV XML, wherever DV and OpenCV put it ---------------------------


def _dv_camera_struct(fs, cam, node, **inside):
    fs.startWriteStruct(node, cv2.FILE_NODE_MAP)
    fs.write("camera_matrix", K_of(cam))
    fs.write("distortion_coefficients", np.array([cam["dist"]]))
    fs.write("image_width", cam["width"])
    fs.write("image_height", cam["height"])
    for key, value in inside.items():
        fs.write(key, value)
    fs.endWriteStruct()


def write_dv_xml_model_in_node(path, cam):
    """As cv2.FileStorage writes a camera's struct holding its own lens model."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    _dv_camera_struct(
        fs,
        cam,
        "DVXplorer_DXA00093",
        distortion_model="Equidistant" if cam["model"] == "equidistant" else "RadialTangential",
    )
    fs.write("use_fisheye_model", 0)
    fs.release()


def write_dv_xml_flag_in_node(path, cam):
    """The older flag, in the camera's node."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    _dv_camera_struct(fs, cam, "DVXplorer_DXA00093", use_fisheye_model=int(cam["model"] == "equidistant"))
    fs.release()


def write_dv_xml_by_hand(path, cam):
    """As DV's C++ module writes it, text by hand (two cameras' worth of layout: the model at the top)."""
    (fx, fy), (cx, cy) = cam["f"], cam["c"]
    dist = " ".join(repr(d) for d in cam["dist"])
    path.write_text(
        '<?xml version="1.0"?>\n<opencv_storage>\n<DAVIS346_00000499>\n'
        '  <camera_matrix type_id="opencv-matrix">\n    <rows>3</rows>\n    <cols>3</cols>\n    <dt>d</dt>\n'
        f"    <data>\n      {fx!r} 0. {cx!r} 0. {fy!r} {cy!r} 0. 0. 1.</data></camera_matrix>\n"
        '  <distortion_coefficients type_id="opencv-matrix">\n    <rows>1</rows>\n'
        f"    <cols>{len(cam['dist'])}</cols>\n    <dt>d</dt>\n    <data>\n      {dist}</data></distortion_coefficients>\n"
        f"  <image_width>{cam['width']}</image_width>\n  <image_height>{cam['height']}</image_height>\n"
        "</DAVIS346_00000499>\n<use_fisheye_model>0</use_fisheye_model>\n<type>camera</type>\n"
        f"<distortion_model>{'Equidistant' if cam['model'] == 'equidistant' else 'RadialTangential'}</distortion_model>\n"
        "</opencv_storage>\n"
    )


@pytest.mark.parametrize(
    "write, suffix",
    [
        (write, suffix)
        for write in (write_dv_xml, write_dv_legacy_xml, write_dv_xml_model_in_node, write_dv_xml_flag_in_node)
        for suffix in (".xml", ".yaml")
    ]
    + [(write_dv_xml_by_hand, ".xml")],
)
@pytest.mark.parametrize("cam", [FISHEYE, RADTAN], ids=lambda c: c["model"])
def test_every_dv_layout_gives_its_lens(tmp_path, write, suffix, cam):
    """The lens model read where each writer puts it (a fisheye's k3 k4 are never taken for p1 p2),
    in FileStorage's XML and YAML forms (DV's own C++ writes XML)."""
    path = tmp_path / f"calibration{suffix}"
    write(path, cam)
    assert_camera(read_calibration(path), cam)


def _write_dv(path, top: dict, **inside):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    _dv_camera_struct(fs, FISHEYE, "DVXplorer_DXA00093", **inside)
    for key, value in top.items():
        fs.write(key, value)
    fs.release()


@pytest.mark.parametrize(
    "top, inside, message",
    [
        (
            {"distortion_model": "RadialTangential"},
            {"distortion_model": "Equidistant"},
            r"DVXplorer_DXA00093/distortion_model says equidistant; distortion_model says radtan: which lens\?",
        ),
        (
            {"use_fisheye_model": 1},
            {"distortion_model": "RadialTangential"},
            r"DVXplorer_DXA00093/distortion_model says radtan; use_fisheye_model says equidistant \(a fisheye\)",
        ),
        ({}, {"use_fisheye_model": 2}, r"DVXplorer_DXA00093/use_fisheye_model: expected 0 or 1"),
        (
            {},
            {"lens": {"distortion_model": "Equidistant"}},
            r"DVXplorer_DXA00093/lens/distortion_model: a lens model key where it is not read",
        ),
        (
            {"settings": {"use_fisheye_model": 1}},
            {},
            r"settings/use_fisheye_model: a lens model key where it is not read",
        ),
    ],
)
def test_a_dv_lens_key_is_read_or_refused_never_ignored(tmp_path, top, inside, message):
    path = tmp_path / "calibration.xml"
    nested = {k: v for k, v in {**top, **inside}.items() if isinstance(v, dict)}
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    _dv_camera_struct(fs, FISHEYE, "DVXplorer_DXA00093", **{k: v for k, v in inside.items() if k not in nested})
    for key, value in top.items():
        if key not in nested:
            fs.write(key, value)
    fs.release()
    for key, table in nested.items():  # a struct inside the camera's node or at the top level
        text = path.read_text()
        body = "".join(f"<{k}>{v}</{k}>" for k, v in table.items())
        anchor = "</DVXplorer_DXA00093>" if key in inside else "</opencv_storage>"
        path.write_text(text.replace(anchor, f"<{key}>{body}</{key}>\n{anchor}"))
    with pytest.raises(DataError, match=rf"^{path}: {message}") as info:
        read_calibration(path)
    assert "\n" not in str(info.value)


# -- every value checked ------------------------------------------------------------------


@pytest.mark.parametrize(
    "fmt, damage, message",
    [
        (
            "kalibr",
            lambda t: t.replace("[346, 260]", "[.nan, 260]"),
            r"cam0.resolution: the sensor size must be two whole numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("[346, 260]", "[346, .inf]"),
            r"cam0.resolution: the sensor size must be two whole numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("[346, 260]", "[346.5, 260]"),
            r"cam0.resolution: the sensor size must be two whole numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("[346, 260]", "[0, 260]"),
            r"cam0.resolution: the sensor size must be two whole numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("[346, 260]", "[1.0e+300, 260]"),
            r"cam0.resolution: the sensor size must be two whole numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("[346, 260]", "[100000, 260]"),
            r"cam0.resolution: the sensor size must be two whole numbers",
        ),
        (
            "kalibr",
            lambda t: t.replace("intrinsics: [259.351", "intrinsics: [.nan"),
            r"cam0.intrinsics: intrinsics and distortion must be finite",
        ),
        (
            "kalibr",
            lambda t: t.replace("intrinsics: [259.351", "intrinsics: [-259.351"),
            r"cam0.intrinsics: focal lengths fx = -259.351",
        ),
        (
            "kalibr",
            lambda t: t.replace("176.201, 131.517", ".inf, 131.517"),
            r"cam0.intrinsics: intrinsics and distortion must be finite",
        ),
        (
            "kalibr",
            lambda t: t.replace("-0.3605", "-.inf"),
            r"cam0.distortion_coeffs: intrinsics and distortion must be finite",
        ),
        (
            "camera_info",
            lambda t: t.replace("image_width: 346", "image_width: 0"),
            r"image_width, image_height: the sensor size must be",
        ),
        (
            "camera_info",
            lambda t: t.replace("image_height: 260", "image_height: 99999"),
            r"image_width, image_height: the sensor size",
        ),
        (
            "camera_info",
            lambda t: t.replace("data: [259.351, 0,", "data: [.nan, 0,"),
            r"camera_matrix/distortion_coefficients: intrinsics and",
        ),
        (
            "dv_xml",
            lambda t: t.replace("<image_width>346</image_width>", "<image_width>0</image_width>"),
            r"DAVIS346_00000499/image_width, image_height: the sensor size must be",
        ),
        ("dv_xml", lambda t: t.replace("259.351 0.", ".Nan 0.", 1), r"DAVIS346_00000499/camera_matrix: intrinsics and"),
        (
            "dv_xml",
            lambda t: t.replace("-0.36049999999999999", "-.Inf"),
            r"DAVIS346_00000499/distortion_coefficients: intrinsics and",
        ),
    ],
)
def test_every_value_is_checked_naming_the_file_and_key(tmp_path, fmt, damage, message):
    path = tmp_path / NAMES[fmt]
    WRITERS[fmt](path, RADTAN)
    damaged = damage(path.read_text())
    assert damaged != path.read_text()
    path.write_text(damaged)
    with pytest.raises(DataError, match=message) as info:
        read_calibration(path, width=346, height=260)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


# -- frames of another size than the calibration's ----------------------------------------


def test_check_frame_size_names_both_sizes(tmp_path):
    from eas_vo.datasets.calibration import check_frame_size

    path = tmp_path / NAMES["kalibr"]
    write_kalibr(path, RADTAN)
    camera = read_calibration(path)
    check_frame_size(camera, 346, 260, "x")
    for width, height in ((240, 180), (640, 480), (260, 346)):
        with pytest.raises(
            DataError,
            match=rf"^rec.bag:/dvs/image_raw:7: the calibration is for 346x260 px, "
            rf"the frames are {width}x{height}$",
        ):
            check_frame_size(camera, width, height, "rec.bag:/dvs/image_raw:7")


# -- lenses whose projection folds back inside the sensor -----------------------------------

#: Lenses within every coefficient range that fold inside the DAVIS346 of FISHEYE / RADTAN: an
#: equidistant model whose angle grows only to 0.19 rad (it then turns back, 43 px from the
#: centre), and a radtan k1 = -0.9 (r (1 + k1 r^2) peaks at r = 0.61, 105 px at f = 259).
FOLDING = {
    "equidistant": {**FISHEYE, "dist": [-9.9, 9.9, -9.9, 9.9]},
    "radtan": {**RADTAN, "dist": [-0.9, 0.0, 0.0, 0.0, 0.0]},
}


@pytest.mark.parametrize(
    "fmt, model", [(fmt, model) for fmt in WRITERS for model in FOLDING if fmt != "ecd" or model == "radtan"]
)
def test_a_lens_that_folds_inside_the_sensor_is_refused_naming_model_and_radius(tmp_path, fmt, model):
    cam = FOLDING[model]
    path = tmp_path / NAMES[fmt]
    WRITERS[fmt](path, cam)
    with pytest.raises(
        DataError,
        match=rf"the {model} lens \(.*\) folds back \d+\.\d px from the principal point "
        rf"\(\d\.\d+ rad off the optical axis\), inside the 346x260 sensor",
    ) as info:
        read_calibration(path, width=346, height=260)
    message = str(info.value)
    assert message.startswith(f"{path}:") and "\n" not in message
    camera = CameraModel(346, 260, K_of(cam), np.array((cam["dist"] + [0.0] * 5)[: len(LENS_MODELS[model])]), model)
    fold_px, fold_rad, _ = camera.fold()
    assert f"{fold_px:.1f} px" in message and f"({fold_rad:.3f} rad" in message
    # the ray at that angle lands where the message says: the farthest any ray reaches on that line
    ray = np.array([[np.sin(fold_rad), 0.0, np.cos(fold_rad)]])
    assert camera.project(ray)[0, 0] - K_of(cam)[0, 2] == pytest.approx(
        fold_px * K_of(cam)[0, 0] / camera.focal_px, rel=1e-6
    )


def test_the_lenses_of_real_cameras_do_not_fold(tmp_path):
    """The DAVIS346 fisheye and radtan lenses above and the ECD's DAVIS240C (k1 = -0.37) grow
    over their whole sensors."""
    for cam in (FISHEYE, RADTAN):
        path = tmp_path / NAMES["kalibr"]
        write_kalibr(path, cam)
        assert read_calibration(path).fold() is None
    assert ECD_DAVIS240.fold() is None and MVSEC_LEFT.fold() is None


def test_an_ecd_calib_txt_reads_comment_lines_as_every_table_does():
    from eas_vo.datasets.calibration import parse_ecd_calib

    plain = parse_ecd_calib(b"199.1 198.9 120.5 90.2 -0.3 0.1 0 0\n", "calib.txt", 240, 180)
    commented = parse_ecd_calib(
        b"# fx fy cx cy k1 k2 p1 p2\r\n199.1 198.9 120.5 90.2 -0.3 0.1 0 0\n", "calib.txt", 240, 180
    )
    assert np.array_equal(plain.K, commented.K) and np.array_equal(plain.dist, commented.dist)
