"""Shared fixtures: an isolated cache, a short simulated sequence, the real ECD excerpts."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

# Keep the user's cache out of the tests (and the tests' sequences out of the user's cache).
os.environ.setdefault("EAS_VO_CACHE_DIR", tempfile.mkdtemp(prefix="eas-vo-test-cache-"))

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SHAPES_ROTATION = SHARED_DATA / "ecd" / "shapes_rotation_0-30s"
EVENT_WINDOWS = SHARED_DATA / "ecd" / "event_windows"


def require(path: Path) -> Path:
    """Skip the test, saying why, when a real-data folder is absent."""
    if not path.exists():
        pytest.skip(f"real data not available: {path} is absent (it lives in ../shared/data beside the repository)")
    return path


def assert_rotations_close(R_a, R_b, tol_rad: float) -> None:
    """Manifold-aware comparison of rotation stacks: every geodesic angle below tol_rad."""
    from eas_vo.geometry import geodesic_angle

    angles = np.atleast_1d(geodesic_angle(np.asarray(R_a), np.asarray(R_b)))
    assert angles.max() <= tol_rad, f"largest rotation difference {angles.max():.3g} rad > {tol_rad:.3g} rad"


@pytest.fixture(scope="session")
def short_sequence(tmp_path_factory) -> Path:
    """A 2-second simulated sequence (seed 3), written once per test session."""
    from eas_vo.datasets.simulator import SimConfig, simulate

    folder = tmp_path_factory.mktemp("sim") / "short"
    simulate(SimConfig(duration_s=2.0, seed=3), folder)
    return folder


@pytest.fixture
def sequence_copy(short_sequence, tmp_path) -> Path:
    """A private copy of the short sequence that a test may damage."""
    import shutil

    dst = tmp_path / "seq"
    shutil.copytree(short_sequence, dst)
    return dst
