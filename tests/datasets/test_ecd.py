"""The Event Camera Dataset folder reader, on simulator output and on the real excerpt."""

import shutil

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eas_vo.camera import CameraModel
from eas_vo.datasets.ecd import CAMCHAIN, EcdFolderDataset, camchain_yaml, write_ecd_folder
from eas_vo.errors import DataError
from eas_vo.types import EVENT_DTYPE
from helpers import SHAPES_ROTATION, hostile_number, hostile_settings, numeric_rows, require


def test_reads_a_simulated_sequence(short_sequence):
    ds = EcdFolderDataset(short_sequence)
    times = ds.frame_times()
    assert 35 <= len(times) <= 41 and np.allclose(np.diff(times), 0.05)
    frame = ds.load_frame(0)
    assert frame.dtype == np.uint8 and frame.shape == (180, 240)
    ev = ds.events()
    assert ev.dtype == EVENT_DTYPE and len(ev) > 100_000 and (np.diff(ev["t"]) >= 0).all()
    assert ds.ground_truth.t[1] - ds.ground_truth.t[0] == pytest.approx(0.005)
    assert ds.imu is not None and len(ds.imu.t) == len(ds.ground_truth.t)
    assert ds.camera.dist[0] != 0  # the simulated lens distorts


def test_samples_give_views_of_the_events(short_sequence):
    ds = EcdFolderDataset(short_sequence)
    samples = list(ds.samples(start_s=0.5, duration_s=0.5))
    assert len(samples) == 10 and samples[0].t == pytest.approx(ds.frame_times()[0] + 0.5)
    for s in samples:
        assert s.events_after["t"][0] >= s.t and (s.event_index == 0 or s.events["t"][s.event_index - 1] < s.t)
        assert np.shares_memory(s.events_after, ds.events())
    for a, b in zip(samples, samples[1:]):
        assert b.prev_event_index == a.event_index


def test_reads_the_real_excerpt():
    ds = EcdFolderDataset(require(SHAPES_ROTATION))
    assert len(ds.frame_times()) == 681 and ds.load_frame(680).shape == (180, 240)
    assert ds.camera.K[0, 0] == pytest.approx(199.092366542) and ds.camera.dist[0] == pytest.approx(-0.368436311798)
    assert len(ds.events()) == 9058 and ds.events()["t"][-1] < 0.5
    assert len(ds.ground_truth.t) == 6010 and ds.imu is None


def test_missing_images_txt_and_events_txt(sequence_copy):
    (sequence_copy / "images.txt").unlink()
    (sequence_copy / "events.txt").unlink()
    with pytest.raises(DataError, match="images.txt: file not found, and there is no events.txt either"):
        EcdFolderDataset(sequence_copy)


def test_missing_frame_file_names_images_txt_line(sequence_copy):
    (sequence_copy / "images" / "frame_00000003.png").unlink()
    with pytest.raises(DataError, match=r"images.txt:4: frame file images/frame_00000003.png does not exist"):
        EcdFolderDataset(sequence_copy)


@pytest.mark.parametrize("name", ["../outside.png", "images/../../outside.png", "/etc/passwd", "C:\\frames\\a.png"])
def test_frames_named_outside_the_dataset_are_refused(sequence_copy, name):
    (sequence_copy.parent / "outside.png").write_bytes((sequence_copy / "images" / "frame_00000000.png").read_bytes())
    lines = (sequence_copy / "images.txt").read_text().splitlines()
    lines[2] = f"{lines[2].split()[0]} {name}"
    (sequence_copy / "images.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"images.txt:3: frame path .* leaves the dataset folder"):
        EcdFolderDataset(sequence_copy)


def png_header(width: int, height: int) -> bytes:
    """The first 33 bytes of a PNG claiming this size (no image data: decoding would fail)."""
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))


def test_a_frame_of_the_wrong_size_is_refused_by_its_header(sequence_copy):
    (sequence_copy / "images" / "frame_00000004.png").write_bytes(png_header(20000, 20000))
    ds = EcdFolderDataset(sequence_copy)
    with pytest.raises(DataError, match=r"frame 4 is 20000x20000, expected 240x180 \(images.txt line 5\)"):
        ds.load_frame(4)


def test_an_odd_first_frame_is_blamed_not_the_good_ones(sequence_copy):
    (sequence_copy / "images" / "frame_00000000.png").write_bytes(png_header(346, 260))
    with pytest.raises(
        DataError, match=r"frame_00000000.png: frame 0 is 346x260 where the frames after it are 240x180"
    ):
        EcdFolderDataset(sequence_copy)


def test_frames_no_event_camera_has_are_refused_from_the_first(sequence_copy):
    """Two huge first frames outvote the good third: the size limit blames frame 0, not frame 2."""
    for k in (0, 1):
        (sequence_copy / "images" / f"frame_{k:08d}.png").write_bytes(png_header(20000, 20000))
    with pytest.raises(DataError, match=r"frame_00000000.png: frame 0 is 20000x20000, not an event camera's frame"):
        EcdFolderDataset(sequence_copy)


def test_unreadable_frame_is_reported_with_its_index(sequence_copy):
    (sequence_copy / "images" / "frame_00000005.png").write_bytes(b"not a png")
    ds = EcdFolderDataset(sequence_copy)
    with pytest.raises(DataError, match=r"cannot decode frame 5 \(images.txt line 6\)"):
        ds.load_frame(5)
    (sequence_copy / "images" / "frame_00000002.png").write_bytes(b"not a png")  # among the first three: at once
    with pytest.raises(DataError, match=r"cannot decode frame 2 \(images.txt line 3\)"):
        EcdFolderDataset(sequence_copy)


@pytest.mark.parametrize("door", ["folder", "zip"])
@pytest.mark.parametrize(
    "content,says",
    [
        (b"", "cannot decode frame 5: the file is empty"),
        (b"P5\n99999 99999\n255\n", "cannot decode frame 5"),  # a header OpenCV raises on, not returns None
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\xf0", "cannot decode frame 5"),  # cut inside its size
    ],
)
def test_an_empty_or_refused_frame_names_its_file_and_index(sequence_copy, tmp_path, door, content, says):
    (sequence_copy / "images" / "frame_00000005.png").write_bytes(content)
    location = sequence_copy if door == "folder" else shutil.make_archive(str(tmp_path / "seq"), "zip", sequence_copy)
    ds = EcdFolderDataset(location)
    with pytest.raises(DataError, match=rf"frame_00000005.png: {says} \(images.txt line 6\)"):
        ds.load_frame(5)


def test_bad_ground_truth_line(sequence_copy):
    path = sequence_copy / "groundtruth.txt"
    lines = path.read_text().splitlines()
    lines[9] = lines[9] + " 7"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"groundtruth.txt:10: expected 8 columns"):
        EcdFolderDataset(sequence_copy)


def test_bad_calibration(sequence_copy):
    (sequence_copy / "calib.txt").write_text("200 200 120\n")
    with pytest.raises(DataError, match="calib.txt:1: expected 4, 8 or 9"):
        EcdFolderDataset(sequence_copy)


#: A fisheye for the simulated sequences' 240x180 frames.
FISHEYE_240 = CameraModel(
    240,
    180,
    np.array([[150.5, 0.0, 120.25], [0.0, 150.75, 89.5], [0.0, 0.0, 1.0]]),
    np.array([-0.048, 0.0113, -0.0554, 0.0215]),
    "equidistant",
)


def test_a_fisheye_sequence_carries_its_camera_as_a_kalibr_camchain(sequence_copy):
    (sequence_copy / "calib.txt").unlink()
    (sequence_copy / CAMCHAIN).write_text(camchain_yaml(FISHEYE_240))
    camera = EcdFolderDataset(sequence_copy).camera
    assert camera.model == "equidistant" and (camera.width, camera.height) == (240, 180)
    np.testing.assert_array_equal(camera.K, FISHEYE_240.K)
    np.testing.assert_array_equal(camera.dist, FISHEYE_240.dist)


def test_the_ecd_calib_txt_takes_no_fisheye(tmp_path):
    with pytest.raises(ValueError, match="radtan cameras go into calib.txt"):
        camchain_yaml(CameraModel.from_calib([200, 200, 120, 90]))
    write_ecd_folder(tmp_path, FISHEYE_240, np.array([0.0]), [np.zeros((180, 240), np.uint8)], np.zeros(0, EVENT_DTYPE))
    assert not (tmp_path / "calib.txt").exists() and EcdFolderDataset(tmp_path).camera.model == "equidistant"


@pytest.mark.parametrize(
    "edit, says",
    [
        (
            lambda t: t.replace("equidistant", "omni"),
            r"distortion_model: 'omni' is not read \(one of radtan, plumb_bob",
        ),
        (lambda t: t.replace("pinhole", "ds"), r"cam0.camera_model: 'ds' is not read \(pinhole only\)"),
        (
            lambda t: t.replace("  resolution: [240, 180]\n", ""),
            r"cam0.resolution: expected a list of 2 numbers, found missing",
        ),
        (
            lambda t: t.replace("[240, 180]", "[346, 260]"),
            r"cam0.resolution: the calibration is for 346x260 px, the frames are 240x180",
        ),
        (
            lambda t: t.replace("-0.048, ", ""),
            r"cam0.distortion_coeffs: the equidistant lens model takes 4 distortion coefficients",
        ),
        (lambda t: t.replace("-0.048", ".nan"), r"cam0.distortion_coeffs: intrinsics and distortion must be finite"),
        (
            lambda t: t.replace("-0.048", "-48.0"),
            r"cam0.distortion_coeffs: distortion k1 k2 k3 k4 = -48 .* out of range",
        ),
        (lambda t: t.replace("150.5", "1.5"), r"cam0.intrinsics: focal lengths fx = 1.5"),
        (lambda t: t.replace("cam0:", "cam1:"), r"no camera 'cam0'; found cam1"),
        (lambda t: t + "  [: oops", r"not valid YAML"),
    ],
)
def test_a_bad_camchain_is_one_line_naming_the_file_and_key(sequence_copy, edit, says):
    (sequence_copy / "calib.txt").unlink()
    (sequence_copy / CAMCHAIN).write_text(edit(camchain_yaml(FISHEYE_240)))
    with pytest.raises(DataError, match=f"camchain.yaml:( 8:|8:)? {says}") as raised:
        EcdFolderDataset(sequence_copy)
    assert "\n" not in str(raised.value)


@hostile_settings()
@given(st.lists(st.lists(hostile_number(), max_size=9).map(" ".join), max_size=8).map("\n".join))
def test_hostile_tables_are_named_errors_or_read_exactly(sequence_copy, content):
    """groundtruth.txt, calib.txt, imu.txt, images.txt replaced by number-like junk: a one-line
    error naming the file, or (accepted) exactly the values the file holds."""
    for name in ("groundtruth.txt", "calib.txt", "imu.txt", "images.txt"):
        original = (sequence_copy / name).read_bytes()
        (sequence_copy / name).write_text(content)
        try:
            ds = EcdFolderDataset(sequence_copy)
        except DataError as exc:
            assert name in str(exc) and "\n" not in str(exc)
            continue
        finally:
            (sequence_copy / name).write_bytes(original)
        rows = numeric_rows(content)
        if name == "groundtruth.txt":
            got = np.column_stack([ds.ground_truth.t, ds.ground_truth.p_w_c, ds.ground_truth.q_w_c]).reshape(-1, 8)
            np.testing.assert_allclose(got, np.array(rows).reshape(-1, 8), rtol=0, atol=1e-2)  # q renormalised
            np.testing.assert_array_equal(got[:, :4], np.array(rows).reshape(-1, 8)[:, :4])
        elif name == "imu.txt":
            got = np.column_stack([ds.imu.t, ds.imu.acc, ds.imu.gyro]).reshape(-1, 7)
            np.testing.assert_array_equal(got, np.array(rows).reshape(-1, 7))
        elif name == "calib.txt":
            values = [v for row in rows for v in row]
            np.testing.assert_array_equal(ds.camera.calib_values()[: len(values)], values)
        else:  # no listed frame exists, so only an empty list can be accepted: an event-only stream
            assert rows == [] and ds.load_frame(0) is None


@pytest.mark.parametrize(
    "name, damage, message",
    [
        (
            "groundtruth.txt",
            lambda rows: rows[:3] + [rows[3].split()[0] + " 0 0 0 0 0 0 2"] + rows[4:],
            "quaternion norm 2.000 is not 1",
        ),
        ("groundtruth.txt", lambda rows: rows[:3] + [rows[1]] + rows[4:], "does not increase"),
        ("imu.txt", lambda rows: rows[:3] + [rows[1]] + rows[4:], "does not increase"),
    ],
)
def test_table_errors_name_the_file_line_past_comments_and_blanks(sequence_copy, name, damage, message):
    """Row 3 (from 0) is damaged; two comment lines and a blank line precede it: file line 7."""
    path = sequence_copy / name
    rows = path.read_text().splitlines()
    damaged = damage(rows)
    path.write_text("\n".join(["# a header", "", "# another"] + damaged) + "\n")
    with pytest.raises(DataError, match=rf"{name}:7: .*{message}"):
        EcdFolderDataset(sequence_copy)


@pytest.mark.parametrize("damage", ["cut", "crc"])
def test_a_damaged_png_is_one_line_on_stderr_not_libpngs_too(sequence_copy, tmp_path, damage):
    from helpers import run_eas_vo

    frame = sequence_copy / "images" / "frame_00000003.png"
    data = bytearray(frame.read_bytes())
    if damage == "cut":
        data = data[: len(data) // 2]
    else:
        data[len(data) // 2] ^= 0xFF  # inside the image data: its CRC fails
    frame.write_bytes(bytes(data))
    done = run_eas_vo(
        "run",
        "--dataset",
        str(sequence_copy),
        "--frontend",
        "original",
        "--duration",
        "1",
        "--out",
        str(tmp_path / "out"),
        "--quiet",
    )
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert "frame_00000003.png: cannot decode frame 3" in done.stderr
