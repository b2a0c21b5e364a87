"""Property-based tests: hostile bytes into every reader and the config loader end in a
one-line DataError/ConfigError naming the place, or (lenient) in counted drops; never
another exception, never a silently shortened result.

Settings: 150 examples per reader (derandomized, no deadline), see SETTINGS.
"""

import io
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eas_vo.errors import DataError, EasVoError
from eas_vo.eventfile import DataWarnings, convert_text_to_cache

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

number = st.one_of(
    st.integers(-10, 400).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(0, 100).map(lambda v: f"{v:.9f}"),
    st.sampled_from(["nan", "inf", "-1", "1e309", "0x10", "", "abc", "1.2.3", "٣"]),
)
line = st.one_of(
    st.tuples(st.floats(0, 10).map(lambda v: f"{v:.6f}"), st.integers(0, 239), st.integers(0, 179), st.integers(0, 1)).map(
        lambda r: " ".join(map(str, r))
    ),
    st.lists(number, min_size=0, max_size=6).map(" ".join),
    st.binary(max_size=20).map(lambda b: b.decode("latin-1")),
)
text = st.lists(line, max_size=40).map("\n".join).map(lambda s: s.encode("utf-8", "replace"))


def valid_row(raw: bytes) -> bool:
    parts = raw.split()
    if len(parts) != 4:
        return False
    try:
        t, x, y, p = (float(v) for v in parts)
    except ValueError:
        return False
    return np.isfinite(t) and 0 <= x < 240 and 0 <= y < 180 and x == int(x) and y == int(y) and p in (0, 1, -1)


def parse(data: bytes, lenient: bool):
    out, warnings = io.BytesIO(), DataWarnings()
    n = convert_text_to_cache(io.BytesIO(data), "events.txt", out, 240, 180, 1e-6, lenient, warnings, block_bytes=64)
    return n, warnings


@SETTINGS
@given(text)
def test_event_text_strict(data):
    lines = [raw for raw in data.split(b"\n") if raw.strip()]
    try:
        n, _ = parse(data, lenient=False)
    except DataError as exc:
        assert "\n" not in str(exc) and exc.line is not None and 1 <= exc.line <= data.count(b"\n") + 1
        return
    assert n == len(lines)  # accepted: nothing was lost


@SETTINGS
@given(text)
def test_event_text_lenient_counts_every_drop(data):
    lines = [raw for raw in data.split(b"\n") if raw.strip()]
    n, warnings = parse(data, lenient=True)
    assert n + sum(warnings.counts.values()) == len(lines)


@SETTINGS
@given(data=st.binary(max_size=400), cut=st.integers(0, 400))
def test_truncated_or_garbage_zip(tmp_path_factory, short_sequence, data, cut):
    from eas_vo.pipeline import open_dataset

    path = tmp_path_factory.mktemp("z") / "seq.zip"
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        for name in ("calib.txt", "images.txt", "events.txt"):
            zf.writestr(name, (short_sequence / name).read_bytes()[:2000] if name != "images.txt" else b"")
    blob = buffer.getvalue()
    path.write_bytes(blob[: len(blob) * cut // 400] + data)
    try:
        open_dataset(str(path)).events()
    except DataError as exc:
        assert "\n" not in str(exc) and "seq.zip" in str(exc)


@SETTINGS
@given(st.lists(st.lists(number, max_size=9).map(" ".join), max_size=8).map("\n".join))
def test_ground_truth_calib_imu_and_image_list(sequence_copy, tmp_path_factory, content):
    from eas_vo.datasets.ecd import EcdFolderDataset

    for name in ("groundtruth.txt", "calib.txt", "imu.txt", "images.txt"):
        original = (sequence_copy / name).read_bytes()
        (sequence_copy / name).write_text(content)
        try:
            EcdFolderDataset(sequence_copy)
        except DataError as exc:
            assert name in str(exc) and "\n" not in str(exc)
        finally:
            (sequence_copy / name).write_bytes(original)


@SETTINGS
@given(key=st.sampled_from(["frontend.n", "frontend.beta", "frontend.sigma_px", "tracker.threshold1", "tracker.max_corners",
                            "run.start_s", "run.duration_s", "backend.x", "nosuch.key", "frontend"]),
       value=st.one_of(number, st.text(max_size=8)))
def test_config_values(key, value):
    from eas_vo.config import resolve

    try:
        resolve(None, {}, [f"{key}={value}"])
    except EasVoError as exc:
        assert "\n" not in str(exc)


@SETTINGS
@given(st.binary(max_size=300))
def test_config_files(tmp_path_factory, data):
    from eas_vo.config import resolve

    path = tmp_path_factory.mktemp("c") / "c.toml"
    path.write_bytes(data)
    try:
        resolve(path)
    except EasVoError as exc:
        assert "\n" not in str(exc).strip()


@pytest.fixture(scope="module")
def bag_bytes(short_sequence, tmp_path_factory):
    from eas_vo.datasets.rosbag import write_bag
    from eas_vo.pipeline import open_dataset

    path = tmp_path_factory.mktemp("bag") / "seq.bag"
    write_bag(open_dataset(str(short_sequence)), path, events_per_message=50_000)
    return path.read_bytes()


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(cut=st.floats(0.0, 1.0), flip=st.integers(0, 10**9))
def test_truncated_or_damaged_bag(bag_bytes, tmp_path_factory, cut, flip):
    from eas_vo.pipeline import open_dataset

    data = bytearray(bag_bytes[: int(len(bag_bytes) * cut)])
    if data and flip % 2:
        data[flip % len(data)] ^= 0xFF
    path = tmp_path_factory.mktemp("b") / "seq.bag"
    path.write_bytes(bytes(data))
    try:
        ds = open_dataset(str(path))
        ds.events()
    except DataError as exc:
        assert "seq.bag" in str(exc) and "\n" not in str(exc)
