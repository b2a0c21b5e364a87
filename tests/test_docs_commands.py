"""Every `eas-vo ...` and `python benchmarks/...` line in README.md and docs/*.md runs as
written and exits 0, page by page in the page's order (a later line may read what an earlier
one wrote), each page in a folder of its own. What a user has and the suite must not fetch or
wait for is stood in for, the same way for every line:

- `path/to/NAME` and the recordings the pages name (`recording.aedat4`, `rec346.bag`, ...) are
  short simulated sequences (2 s, 240x180) written in that format by its own tools;
- network fetches: the data folder already holds stand-in zips of every Event Camera Dataset
  sequence (under their names, with a registry of their MD5s) and an ORB vocabulary, so
  `fetch` and `reproduce` find them there, as they do offline (docs/datasets.md);
- long work: the embedded synthetic sequences are simulated for 1 s (`--set
  dataset.duration_s=1`), `--duration` is at most 1.5 s (`reproduce` included), `--runs`
  1 (`slam`, `reproduce table2`), a benchmark's `--repeat` 1, a `--sweep` takes its first two values, a viewer is not spawned (`--spawn`
  dropped), and the research benchmarks get `--smoke` (their protocol on 1 s of each sequence
  and the first item of each list: a check that the command runs, its figures mean nothing).

The pages say so where they list commands (README.md, "Documentation")."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eas_vo.cli.main import main
from helpers import REPOSITORY, publish_sequences, shell_commands, write_aedat4, write_dv_xml, write_mvsec

PAGES = [REPOSITORY / "README.md", *sorted((REPOSITORY / "docs").glob("*.md"))]
#: Command lines that are set-up, not eas-vo's (the README's install lines, pip's extras).
NOT_OURS = re.compile(r"^(python3? -m venv|\S*pip |\S*ruff |\S*python -m pytest|python3? -c )")
MAX_DURATION_S = 1.5
#: The length [s] the embedded synthetic sequences are simulated for (`--set dataset.duration_s`).
SIMULATED_S = 1.0
#: The commands and benchmarks that take `--set dataset.KEY=VALUE`.
TAKE_SET = ("run", "compare", "export", "slam", "vocabulary", "render", "info", "convert")
BENCHMARKS_TAKING_SET = ("bench_pipeline.py", "bench_slam.py")
#: Event Camera Dataset names a page may fetch: stand-in zips in the data folder.
ECD_NAMES = ("hdr_boxes", "hdr_poster", "shapes_rotation", "poster_rotation", "boxes_rotation", "dynamic_rotation")
#: Benchmarks that simulate and run a research protocol of their own: run with --smoke.
SMOKE = {"select_best.py", "report_best.py", "light_speed_study.py", "faster_real.py"}


def documented(page: Path) -> list[tuple[dict, list[str]]]:
    """The page's eas-vo and benchmark command lines, in order, as (environment, words)."""
    found = []
    for env, words in shell_commands(page.read_text()):
        line = " ".join(words)
        if NOT_OURS.match(line):
            continue
        if Path(words[0]).name == "eas-vo" or (
            words[0] in ("python", "python3") and words[1].startswith("benchmarks/")
        ):
            found.append((env, words))
    return found


COMMANDED = [page for page in PAGES if documented(page)]


def stood_in(words: list[str]) -> list[str]:
    """The substitutions of the module's docstring for long work (not for paths: the page's
    folder holds the stand-ins under the names the page uses)."""
    words = [w for w in words if w != "--spawn"]
    command = words[1] if Path(words[0]).name == "eas-vo" else None
    for option, cap in (("--duration", MAX_DURATION_S), ("--runs", 1), ("--repeat", 1)):
        if option in words:
            k = words.index(option) + 1
            words[k] = str(type(cap)(min(float(words[k]), cap)))
        elif option == "--runs" and (command == "slam" or words[1:3] == ["reproduce", "table2"]):
            words += ["--runs", "1"]
        elif option == "--duration" and command in ("simulate", "reproduce"):
            words += ["--duration", str(SIMULATED_S if command == "simulate" else MAX_DURATION_S)]
        elif option == "--repeat" and command is None and Path(words[1]).name in ("bench_slam.py", "bench_pipeline.py"):
            words += ["--repeat", "1"]
    if "--sweep" in words:
        k = words.index("--sweep") + 1
        key, _, values = words[k].partition("=")
        words[k] = f"{key}={','.join(values.split(',')[:2])}"
    dataset = words[words.index("--dataset") + 1] if "--dataset" in words else "synthetic:default"
    takes_set = command in TAKE_SET or (command is None and Path(words[1]).name in BENCHMARKS_TAKING_SET)
    if takes_set and dataset.startswith("synthetic:"):
        words += ["--set", f"dataset.duration_s={SIMULATED_S}"]
    if command in ("compare", "reproduce"):
        words += ["--quiet"]
    if command is None and Path(words[1]).name in SMOKE:
        words += ["--smoke"]
    return words


@pytest.fixture(scope="module")
def stand_ins(short_sequence, walk_vocabulary, tmp_path_factory) -> Path:
    """A folder of the recordings and files the pages name, and a data folder (`data/`) with
    the sequences' zips, their registry and an ORB vocabulary."""
    from eas_vo.datasets.bags import BagConfig
    from eas_vo.datasets.rosbag import write_bag
    from eas_vo.datasets.rosbag2 import write_bag2
    from eas_vo.registry import open_dataset
    from eas_vo.slam.orbvoc import NAME

    root = tmp_path_factory.mktemp("stand_ins")
    seq = open_dataset(str(short_sequence))
    to = root / "path" / "to"
    to.mkdir(parents=True)
    for name in (*ECD_NAMES, "shapes_rotation_0-30s"):
        (to / name).symlink_to(short_sequence)
    (root / "shapes_rotation_0-30s").symlink_to(short_sequence)
    events_only = to / "event_only_folder"
    shutil.copytree(short_sequence, events_only, ignore=shutil.ignore_patterns("images*"))
    write_bag(seq, to / "recording.bag")
    (root / "rec346.bag").symlink_to(to / "recording.bag")
    write_bag2(seq, to / "bag_folder", storage="mcap")
    (to / "bag_folder" / "bag_0.mcap").symlink_to(next((to / "bag_folder").glob("*.mcap")).name)
    write_bag2(seq, to / "recording", config=BagConfig(events_topic="/event_camera/events"), encoding="mono")
    (root / "rec346_ros2").symlink_to(to / "bag_folder")
    _aedat4(seq, root)
    _raw(seq, root)
    write_mvsec(root, seq, name="indoor_flying1", side=("left", "right"))
    (root / "mvsec").mkdir()
    (root / "mvsec" / "rec346_data.hdf5").symlink_to(root / "indoor_flying1_data.hdf5")
    _camchain(seq.camera, root / "camchain-imucam-indoor_flying.yaml")
    (root / "ecd346").mkdir()
    for item in short_sequence.iterdir():
        (root / "ecd346" / item.name).symlink_to(item)
    (root / "ecd346" / "camchain.yaml").symlink_to(root / "camchain-imucam-indoor_flying.yaml")
    _tum(seq, root / "KeyFrameTrajectory.txt")
    (root / "their_trajectory.tum").symlink_to(root / "KeyFrameTrajectory.txt")
    data = root / "data"
    data.mkdir()
    publish_sequences(data, {name: short_sequence for name in ECD_NAMES}, root / "registry.txt")
    shutil.copyfile(walk_vocabulary, data / NAME)
    (to / "zips").symlink_to(data)
    return root


def _aedat4(seq, root: Path) -> None:
    """recording.aedat4 (DV's writer: the frames, every 20th event, the IMU), its calibration.xml
    (as DV's calibration writes it) and poses.tum (the ground truth)."""
    ev = np.asarray(seq.events())[::20]
    frames = [(round(t * 1e6), 1000, seq.load_frame(k)) for k, t in enumerate(seq.frame_times())]
    imu = np.column_stack(
        [np.round(seq.imu.t * 1e6), seq.imu.acc / 9.81, np.degrees(seq.imu.gyro)]
    )  # DV's units: g and deg/s
    write_aedat4(
        root / "recording.aedat4",
        size=(seq.camera.width, seq.camera.height),
        events=(np.round(ev["t"] * 1e6).astype(np.int64), ev["x"], ev["y"], ev["p"]),
        frames=frames,
        imu=imu,
    )
    (root / "rec346.aedat4").symlink_to(root / "recording.aedat4")
    cam = seq.camera
    write_dv_xml(
        root / "calibration.xml",
        dict(
            f=(cam.K[0, 0], cam.K[1, 1]),
            c=(cam.K[0, 2], cam.K[1, 2]),
            dist=list(cam.dist),
            width=cam.width,
            height=cam.height,
            model=cam.model,
        ),
        node="DAVIS_test",
    )
    _tum(seq, root / "poses.tum")


def _raw(seq, root: Path) -> None:
    """recording.raw (EVT 3.0, every 20th event) and camera.yaml (a kalibr camchain)."""
    from prophesee_words import EVENT, encode_evt3, write_raw

    ev = np.asarray(seq.events())[::20]
    events = np.zeros(len(ev), EVENT)
    events["t"], events["x"], events["y"], events["p"] = np.round(ev["t"] * 1e6), ev["x"], ev["y"], ev["p"]
    write_raw(root / "recording.raw", encode_evt3(events)[0], "EVT3", seq.camera.width, seq.camera.height)
    _camchain(seq.camera, root / "camera.yaml")


def _camchain(cam, path: Path) -> None:
    """A kalibr camchain of the camera as both cam0 and cam1 (MVSEC's calibration files are
    kalibr's, the left camera cam0, the right cam1)."""
    K = cam.K
    path.write_text(
        "".join(
            f"{name}:\n  camera_model: pinhole\n"
            f"  intrinsics: [{K[0, 0]}, {K[1, 1]}, {K[0, 2]}, {K[1, 2]}]\n"
            f"  distortion_model: radtan\n  distortion_coeffs: [{', '.join(str(d) for d in cam.dist[:4])}]\n"
            f"  resolution: [{cam.width}, {cam.height}]\n"
            for name in ("cam0", "cam1")
        )
    )


def _tum(seq, path: Path) -> None:
    """The sequence's ground truth as a TUM file (another tool's trajectory, a poses file)."""
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum

    gt = seq.ground_truth
    path.write_text(format_tum(gt.t, gt.p_w_c, matrices_from_quats(gt.q_w_c)))


@pytest.mark.slow
@pytest.mark.parametrize("page", COMMANDED, ids=lambda p: str(p.relative_to(REPOSITORY)))
def test_every_documented_command_runs(page, stand_ins, tmp_path, monkeypatch, capsys):
    """The page's command lines, with the stand-ins, exit 0 in order."""
    for entry in stand_ins.iterdir():  # path/to/ a folder of the page's own, which a command may write into
        if entry.name != "path":
            (tmp_path / entry.name).symlink_to(entry)
    (tmp_path / "path" / "to").mkdir(parents=True)
    for entry in (stand_ins / "path" / "to").iterdir():
        (tmp_path / "path" / "to" / entry.name).symlink_to(entry)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("EAS_VO_DATA_DIR", str(stand_ins / "data"))
    monkeypatch.setenv("EAS_VO_DATA_REGISTRY", str(stand_ins / "registry.txt"))
    failed = []
    for env, words in documented(page):
        argv = stood_in(words)
        with monkeypatch.context() as scoped:
            for name, value in env.items():
                scoped.setenv(name, value)
            status, said = _run(argv)
        said += capsys.readouterr().err
        if status != 0:
            failed.append(f"{' '.join(words)} -> {status}: {said[-600:]}")
    assert not failed, "\n".join(failed)


def _run(argv: list[str]) -> tuple[int, str]:
    """`eas-vo` in this process (its status; what it says is captured), a benchmark in a child
    process (its status and standard error)."""
    if Path(argv[0]).name == "eas-vo":
        try:
            return main(argv[1:]), ""
        except SystemExit as stop:
            return int(stop.code or 0), ""
    script = REPOSITORY / argv[1]
    done = subprocess.run([sys.executable, str(script), *argv[2:]], capture_output=True, text=True, env=os.environ)
    return done.returncode, done.stderr
