"""A wrong gyro never gives a confident wrong result: on a simulated sequence with best.toml
(which fuses the gyro and predicts LK from it), every way a gyro goes wrong is refused before
any work, warned about in one line, or gives an APE no worse than the run without the IMU
(plus TOLERANCE_RAD).

Not covered, because it is not met: a constant bias between about 0.03 and 0.15 rad/s, which
the images' own systematic error hides on a 2 s sequence (imu.verdict.MAX_BIAS_RAD_S) and the
pose graph's bias prior (backend.gyro_bias_sigma) does not absorb: at 0.05 rad/s on seed 0 the
run reads 0.069 rad against 0.031 without the IMU."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from eas_vo import pipeline
from eas_vo.config import resolve
from eas_vo.errors import EasVoError

#: How much worse than the run without an IMU an unwarned run may be [rad]: a tenth of a degree
#: of the average APE (the two runs track the same images; their APEs are 0.02-0.04 here).
TOLERANCE_RAD = 0.002


def with_imu(sequence: Path, folder: Path, rows: np.ndarray | None) -> Path:
    """`sequence`'s files linked into `folder`, with `rows` (t ax ay az gx gy gz) as its imu.txt
    (none when None)."""
    folder.mkdir(parents=True)
    for entry in sequence.iterdir():
        if entry.name != "imu.txt":
            os.symlink(entry, folder / entry.name)
    if rows is not None:
        np.savetxt(folder / "imu.txt", rows, fmt="%.9f")
    return folder


def outcome(folder: Path, *assignments: str) -> tuple[str, dict | None]:
    """("refused", None), ("warned", metrics) with a warning on the IMU, or ("silent", metrics)."""
    try:
        result = pipeline.run(resolve("best", {"dataset": str(folder)}, list(assignments)))
    except EasVoError as error:
        assert "\n" not in str(error)
        return "refused", None
    on_imu = [w for w in result.metrics["data_warnings"] if "gyro" in w or "IMU" in w]
    return ("warned" if on_imu else "silent"), result.metrics


@pytest.fixture(scope="module")
def rig(short_sequence, tmp_path_factory):
    """The sequence's IMU rows and the APE [rad] of its run without an IMU and with its own."""
    rows = np.loadtxt(short_sequence / "imu.txt", ndmin=2)
    root = tmp_path_factory.mktemp("imu")
    _, without = outcome(with_imu(short_sequence, root / "none", None))
    said, right = outcome(with_imu(short_sequence, root / "right", rows))
    assert said == "silent" and right["gyro"] == "used" and without["gyro"] is None
    assert right["ape_mean_rad"] < without["ape_mean_rad"]  # the gyro is worth fusing at all
    return short_sequence, rows, without["ape_mean_rad"], root


def swapped(rows):
    out = rows.copy()
    out[:, 4:7] = rows[:, [5, 4, 6]] * [1, -1, 1]  # x -> y, y -> -x: a quarter turn about z
    return out


def scaled(rows, factor, columns=slice(4, 7)):
    out = rows.copy()
    out[:, columns] *= factor
    return out


CASES = {
    "in deg/s": (lambda r: scaled(r, np.degrees(1.0)), ()),
    "all zeros": (lambda r: scaled(r, 0.0), ()),
    "at 1 Hz": (lambda r: r[::200], ()),
    "two readings": (lambda r: r[:2], ()),
    "a 1000 rad/s spike": (lambda r: np.vstack([r[:200], r[200] + [0, 0, 0, 0, 1000, 0, 0], r[201:]]), ()),
    "scaled by 1e6": (lambda r: scaled(r, 1e6), ()),
    "scaled by 20": (lambda r: scaled(r, 20.0), ()),  # within range: misleads LK until nothing is confident
    "scaled by 0.6": (lambda r: scaled(r, 0.6), ()),
    "scaled by 1.5": (lambda r: scaled(r, 1.5), ()),
    "a bias of 0.3 rad/s": (lambda r: r + [0, 0, 0, 0, 0.2, -0.15, 0.15], ()),
    "timestamps in microseconds": (lambda r: scaled(r, 1e6, 0), ()),
    "its clock 1 s off": (lambda r: r, ("run.imu_time_offset_s=1.0",)),
    "axes swapped": (swapped, ()),
    "every sign flipped": (lambda r: scaled(r, -1.0), ()),
    "entirely 100 s early": (lambda r: r - [100, 0, 0, 0, 0, 0, 0], ()),
}


@pytest.mark.parametrize("case", CASES)
def test_a_grossly_wrong_gyro_is_refused_or_not_used(rig, case):
    """Each of these was fused silently (APE 0.13-2.2 rad against 0.03 without the IMU)."""
    sequence, rows, without, root = rig
    make, assignments = CASES[case]
    said, metrics = outcome(with_imu(sequence, root / case.replace(" ", "_"), make(rows)), *assignments)
    if said == "refused":
        return
    assert said == "warned" and metrics["gyro"] == "not used", (case, metrics["data_warnings"])
    assert metrics["ape_mean_rad"] <= without + TOLERANCE_RAD


#: What each perturbation leaves as it was: hypothesis changes one or two of them per example.
UNCHANGED = {
    "axes": np.eye(3),
    "scale": 1.0,
    "bias": np.zeros(3),
    "time_unit": 1.0,
    "offset": 0.0,
    "gap": None,
    "spike": None,
    "every": 1,
}


def perturbed(rows: np.ndarray, drawn: dict, changes: set) -> tuple[np.ndarray, list[str]]:
    """The IMU rows changed as hypothesis drew (`drawn`, only the `changes` of UNCHANGED's keys):
    axes, a scale, a bias, a time unit, a clock offset, a gap, a spike, a rate."""
    how = {key: drawn[key] if key in changes else value for key, value in UNCHANGED.items()}
    out = rows.copy()
    out[:, 4:7] = out[:, 4:7] @ how["axes"].T * how["scale"] + how["bias"]
    out[:, 0] = out[:, 0] * how["time_unit"]
    if how["gap"] is not None:
        start, length = how["gap"]
        keep = (out[:, 0] < start) | (out[:, 0] >= start + length)
        out = out[keep]
    if how["spike"] is not None:
        k, rate = how["spike"]
        out[k % len(out), 4 + k % 3] += rate
    return out[:: how["every"]], [f"run.imu_time_offset_s={how['offset']}"]


def signed_permutations():
    import itertools

    matrices = []
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            R = np.zeros((3, 3))
            R[range(3), order] = signs
            matrices.append(R)
    return matrices


perturbations = st.fixed_dictionaries(
    {
        "axes": st.one_of(
            st.sampled_from(signed_permutations()),
            st.floats(-np.pi, np.pi).map(lambda a: Rotation.from_rotvec([0.3 * a, -0.5 * a, 0.8 * a]).as_matrix()),
        ),
        "scale": st.sampled_from([np.degrees(1.0), np.radians(1.0), 0.5, 0.7, 1.4, 2.0, 1e3, 0.0, -1.0]),
        "bias": st.sampled_from([np.array([0.2, -0.15, 0.1]), np.array([0.0, 0.0, -0.5])]),
        "time_unit": st.sampled_from([1e3, 1e6, 1e9]),
        "offset": st.sampled_from([0.005, -0.02, 0.1, -0.5, 1.0, 100.0]),
        "gap": st.tuples(st.floats(0.0, 1.8), st.floats(0.02, 1.0)),
        "spike": st.tuples(st.integers(0, 399), st.sampled_from([5.0, 30.0, -60.0, 1000.0])),
        "every": st.sampled_from([2, 5, 20, 200]),
    }
)


@settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(drawn=perturbations, changes=st.sets(st.sampled_from(sorted(UNCHANGED)), min_size=1, max_size=2))
def test_any_wrong_gyro_is_refused_warned_or_harmless(rig, drawn, changes):
    sequence, rows, without, root = rig
    made, assignments = perturbed(rows, drawn, changes)
    folder = root / f"h{len(list(root.iterdir()))}"
    said, metrics = outcome(with_imu(sequence, folder, made), *assignments)
    event(said if metrics is None else f"{said}, gyro {metrics['gyro']}")
    assert said != "silent" or metrics["ape_mean_rad"] <= without + TOLERANCE_RAD, (changes, drawn, metrics)


def test_a_run_tracked_again_keeps_one_frames_csv_of_the_tracking_it_used(rig, tmp_path):
    """A gyro 20 times too fast misleads LK until the images can tell nothing; the frames are
    tracked again without it, and the folder holds that tracking's frames.csv only."""
    import csv

    sequence, rows, without, root = rig
    folder = with_imu(sequence, tmp_path / "seq", scaled(rows, 20.0))
    result = pipeline.run(resolve("best", {"dataset": str(folder)}), tmp_path / "out")
    assert result.metrics["gyro"] == "not used" and result.metrics["ape_mean_rad"] <= without + TOLERANCE_RAD
    written = sorted(p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith("."))
    assert written == sorted(pipeline.RUN_FILES + ("groundtruth.tum",))
    with open(tmp_path / "out" / "frames.csv") as f:
        logged = [int(row["inliers"]) for row in csv.DictReader(f)]
    assert logged == [r.inliers for r in result.records]


def test_a_mirrored_gyro_is_named_for_what_it_is(rig):
    """Rates negated (a left-handed axis convention) are no rotation of the IMU: the warning
    says to negate them, not a run.imu_rotvec_cam that cannot undo it."""
    sequence, rows, _, root = rig
    said, metrics = outcome(with_imu(sequence, root / "mirrored", scaled(rows, -1.0)))
    assert said == "warned" and metrics["gyro"] == "not used"
    (line,) = [w for w in metrics["data_warnings"] if "gyro" in w]
    assert "its axes are mirrored" in line and "negate its rates in the file" in line


@pytest.mark.parametrize(
    "reader, assignments",
    [
        ("nothing", ("tracker.predict=none", "backend.gyro=false")),
        ("the backend", ("tracker.predict=none",)),  # best.toml's backend.gyro = "auto"
        ("the tracker", ("backend.gyro=false",)),  # best.toml's tracker.predict = "auto"
    ],
)
def test_only_a_run_that_reads_the_imu_checks_its_clock(short_sequence, tmp_path, reader, assignments):
    """A gyro stamped 40 ms late: a run whose tracker or backend reads it is told the clock the
    images ask for; a run that reads no IMU says nothing of one (nor reports an IMU clock)."""
    late = np.loadtxt(short_sequence / "imu.txt", ndmin=2)
    late[:, 0] += 0.040
    said, metrics = outcome(with_imu(short_sequence, tmp_path / "late", late), *assignments)
    if reader == "nothing":
        assert said == "silent" and metrics["gyro"] is None and "imu_time_offset_s" not in metrics
    else:
        assert said == "warned" and metrics["imu_time_offset_s"] == 0.0
        assert any("run.imu_time_offset_s = 0.0" in w for w in metrics["data_warnings"]), metrics["data_warnings"]
