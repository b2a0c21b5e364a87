"""Shared fixtures: an isolated cache and a short simulated sequence.

The suite tests the *installed* eas-vo (editable or not): the repository root is taken
off `sys.path` first, so that `python -m pytest` run from the root (which puts the
current folder on the path) never imports the source folder `eas_vo/` in place of the
installed package, whose plugins live in `eas_vo.frontends` etc.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import pytest

_ROOT = Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or os.curdir).resolve() != _ROOT]
try:
    import eas_vo  # noqa: F401
except ImportError:
    raise pytest.UsageError("eas-vo is not installed in this Python: pip install -e '.[test]' (see README)") from None

# Keep the user's cache out of the tests (and the tests' sequences out of the user's cache).
os.environ.setdefault("EAS_VO_CACHE_DIR", tempfile.mkdtemp(prefix="eas-vo-test-cache-"))


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
