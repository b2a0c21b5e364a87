"""TUM trajectories (`t tx ty tz qx qy qz qw`, camera-to-world): the one reader and writer."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A TUM trajectory `t tx ty tz qx qy qz qw` -> (t [s], p [m] (N, 3), q_xyzw (N, 4))."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns, found {rows.shape[1]}")
    return rows[:, 0], rows[:, 1:4], rows[:, 4:8]
