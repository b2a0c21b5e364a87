"""The uncertainty a run writes: orientation_sigma.csv (the chain's propagated and the backend's
covariance of every frame's orientation, per axis) and frames.csv's sigma columns (each frame's
step), on 1 s of the embedded default sequence."""

import csv

import numpy as np
import pytest

from eas_vo import config, pipeline
from eas_vo.geometry.uncertainty import axis_sigmas, chain_covariance, consecutive_steps, largest_sigma
from eas_vo.pipeline.outputs import ORIENTATION_SIGMA_FIELDS
from eas_vo.pipeline.tracking import FRAMES_CSV_FIELDS


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def column(table, name) -> np.ndarray:
    return np.array([float(r[name]) if r[name] != "" else np.nan for r in table])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """paper's method with keyframe edges every 3 frames, solved by the chain and by the graph."""
    out = {}
    for backend in ("chain", "gtsam"):
        folder = tmp_path_factory.mktemp(backend) / "run"
        cfg = config.resolve("paper", {"backend": backend, "duration_s": 1.0}, ["tracker.klt.keyframe_interval=3"])
        out[backend] = (pipeline.run(cfg, folder), folder)
    return out


@pytest.mark.parametrize("backend", ["chain", "gtsam"])
def test_orientation_sigma_has_a_row_a_frame_with_the_chains_and_the_backends_sigmas(runs, backend):
    result, folder = runs[backend]
    assert "orientation_sigma.csv" in pipeline.RUN_FILES
    text = (folder / "orientation_sigma.csv").read_text()
    assert text.splitlines()[0] == ",".join(ORIENTATION_SIGMA_FIELDS)
    table = rows(folder / "orientation_sigma.csv")
    frames = rows(folder / "frames.csv")
    n = len(result.t)
    assert len(table) == len(frames) == n == 20
    assert [r["index"] for r in table] == [r["index"] for r in frames]
    assert [r["t"] for r in table] == [r["t"] for r in frames]  # the same clock, written alike
    chain = chain_covariance(n, result.edges)
    np.testing.assert_array_equal(result.chain_covariance, chain)
    for prefix, covariance in (("chain", chain), ("backend", result.covariance)):
        written = np.column_stack([column(table, f"{prefix}_sigma{axis}_deg") for axis in ("", "_x", "_y", "_z")])
        expected = np.degrees(np.column_stack([largest_sigma(covariance), axis_sigmas(covariance)]))
        np.testing.assert_allclose(written, expected, atol=1e-6)
    chain_deg = column(table, "chain_sigma_deg")
    assert chain_deg[0] == 0 and np.all(np.diff(chain_deg) >= -1e-6)  # never shrinks along the chain
    backend_deg = column(table, "backend_sigma_deg")
    if backend == "chain":
        np.testing.assert_array_equal(backend_deg, chain_deg)  # the chain's covariance is the chain's
    else:
        assert backend_deg[-1] < 0.8 * chain_deg[-1]  # keyframe edges: the graph's uncertainty is smaller


def test_frames_csv_gives_each_frames_step_uncertainty(runs):
    result, folder = runs["gtsam"]
    frames = rows(folder / "frames.csv")
    assert list(frames[0]) == list(FRAMES_CSV_FIELDS)
    assert list(FRAMES_CSV_FIELDS[-4:]) == ["sigma_deg", "sigma_x_deg", "sigma_y_deg", "sigma_z_deg"]
    steps = consecutive_steps(result.edges)
    assert frames[0]["status"] == "first" and frames[0]["sigma_deg"] == ""
    measured = 0
    for k, row in enumerate(frames):
        if k not in steps:
            assert [row[f] for f in FRAMES_CSV_FIELDS[-4:]] == [""] * 4, row
            continue
        measured += 1
        edge = steps[k]
        assert float(row["sigma_deg"]) == pytest.approx(np.degrees(edge.sigma_rad), abs=1e-6)
        np.testing.assert_allclose(
            [float(row[f"sigma_{a}_deg"]) for a in "xyz"], np.degrees(edge.sigmas_rad()), atol=1e-6
        )
        assert float(row["sigma_deg"]) >= max(float(row[f"sigma_{a}_deg"]) for a in "xyz") - 1e-6
    assert measured >= 15


def test_a_backend_covariance_of_the_wrong_shape_is_named_in_one_line(sequence_copy, monkeypatch):
    """BackendResult.covariance is (n_frames, 3, 3) or None: anything else is refused naming the backend."""
    from eas_vo.backends.chain import ChainBackend
    from eas_vo.errors import EasVoError
    from eas_vo.plugins import BackendResult

    def solve(self, n, edges, **kw):
        return BackendResult(np.tile(np.eye(3), (n, 1, 1)), covariance=np.zeros((n, 3)))

    monkeypatch.setattr(ChainBackend, "solve", solve)
    cfg = config.resolve(None, {"dataset": str(sequence_copy), "duration_s": 0.5, "backend": "chain"})
    with pytest.raises(EasVoError, match=r"backend 'chain' returned a covariance of shape \(10, 3\)"):
        pipeline.run(cfg)
