"""Any sensor size and lens end to end: every frontend and best.toml on a short 346x260
simulated sequence, paper.toml on a DAVIS346 fisheye, and the fisheye's lens mattering."""

import numpy as np
import pytest

from eas_vo import config, pipeline
from eas_vo.datasets.simulator import SimConfig, simulate
from eas_vo.datasets.simulator.generate import SENSORS
from eas_vo.datasets.synthetic import SyntheticConfig

FRONTENDS = ("original", "histeq", "slice", "eas", "ts", "sits")
DURATION_S = 1.0


@pytest.fixture(scope="module")
def sequences(tmp_path_factory) -> dict:
    """1 s at 346x260: the DAVIS240's lens and field of view (radtan), and MVSEC's DAVIS346 (fisheye)."""
    cameras = {"radtan": SyntheticConfig(width=346, height=260).camera(), "fisheye": SENSORS["davis346"]}
    folders = {}
    for name, camera in cameras.items():
        folders[name] = tmp_path_factory.mktemp(name) / "seq"
        simulate(SimConfig(duration_s=DURATION_S, seed=5, camera=camera), folders[name])
    return folders


def _run(config_name, folder, frontend=None):
    result = pipeline.run(config.resolve(config_name, {"dataset": str(folder), "frontend": frontend}))
    assert len(result.records) == len(np.loadtxt(folder / "images.txt", usecols=0))  # every frame, at 346x260
    return result.metrics


@pytest.mark.parametrize("frontend", FRONTENDS)
def test_every_frontend_tracks_a_346x260_sequence(sequences, frontend):
    """Every frame through every frontend at 346x260 (the pipeline checks each image's size).
    With the paper's chain, ts and sits drift on this second whatever the size (APE 0.51 and
    0.18 rad here, 0.74 and 0.14 at 240x180): only the others are held to an accuracy."""
    ape = _run("paper", sequences["radtan"], frontend)["ape_mean_rad"]
    assert np.isfinite(ape) and (frontend in ("ts", "sits") or ape < 0.1), ape


def test_best_config_tracks_a_346x260_sequence(sequences):
    assert _run("best", sequences["radtan"])["ape_mean_rad"] < 0.05  # 0.011 measured


def test_a_fisheye_is_tracked_through_its_own_lens(sequences, tmp_path):
    """The paper's configuration on the DAVIS346 fisheye; the same frames and events read as a
    pinhole camera (the lens ignored) come out worse."""
    fisheye = _run("paper", sequences["fisheye"])["ape_mean_rad"]
    assert fisheye < 0.1  # 0.033 measured; 0.082 read as a pinhole
    pinhole = tmp_path / "pinhole"
    pinhole.mkdir()
    for item in sequences["fisheye"].iterdir():
        if item.name != "camchain.yaml":
            (pinhole / item.name).symlink_to(item)
    K = SENSORS["davis346"].model().K
    (pinhole / "calib.txt").write_text(" ".join(repr(float(v)) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2])) + "\n")
    assert _run("paper", pinhole)["ape_mean_rad"] > 1.5 * fisheye


@pytest.mark.parametrize("bad_from", [0, 5])
@pytest.mark.parametrize("size", [(346, 260), (640, 480)])
def test_a_dataset_frame_of_another_size_than_the_camera_is_one_line(monkeypatch, short_sequence, bad_from, size):
    """A plugin dataset whose frames are not its camera's size: one line naming the frame and
    both sizes (before any work when it is the first frame), not a traceback in a frontend."""
    import cv2

    from eas_vo import registry
    from eas_vo.errors import EasVoError

    dataset = registry.open_dataset(str(short_sequence))
    load_frame = dataset.load_frame
    monkeypatch.setattr(
        dataset, "load_frame", lambda k: cv2.resize(load_frame(k), size) if k >= bad_from else load_frame(k)
    )
    monkeypatch.setattr(registry, "open_dataset", lambda spec, config=None: dataset)
    cfg = config.resolve(None, {"dataset": str(short_sequence), "frontend": "eas", "backend": "chain"})
    with pytest.raises(
        EasVoError,
        match=rf"^{short_sequence}: frame {bad_from} \(t=[0-9.]+ s\): the calibration is for "
        rf"240x180 px, the frame is {size[0]}x{size[1]}$",
    ):
        pipeline.run(cfg)
