"""What a run produced (`RunResult`) and its files: trajectory.tum, groundtruth.tum,
orientation_sigma.csv, metrics.json and rotation.png."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eas_vo.evaluation.ape import RotationErrors
from eas_vo.geometry.uncertainty import axis_sigmas, largest_sigma
from eas_vo.io.atomic import atomic_path, json_text, write_text_atomic
from eas_vo.io.tables import clock_time
from eas_vo.io.tum import format_tum
from eas_vo.types import FrameRecord, RelativeRotation


@dataclass
class RunResult:
    """Everything a run produced, in memory."""

    t: np.ndarray
    R_w_c: np.ndarray
    records: list[FrameRecord]
    edges: list[RelativeRotation]
    errors: RotationErrors | None
    metrics: dict = field(default_factory=dict)
    causal_R_w_c: np.ndarray | None = None  # an online backend's estimate of each frame when it arrived
    clock_origin_ns: int = 0  # the recording's clock at t = 0 (Dataset.clock_origin_ns), added back in files
    covariance: np.ndarray | None = None  # the backend's of each R_w_c (BackendResult.covariance), or None
    chain_covariance: np.ndarray | None = None  # the chain's, propagated (geometry.uncertainty.chain_covariance)


RUN_FILES = (
    "config.toml",
    "identity.json",
    "frames.csv",
    "trajectory.tum",
    "orientation_sigma.csv",
    "metrics.json",
    "rotation.png",
)
"""What every finished run's folder holds (groundtruth.tum and trajectory_causal.tum when they apply)."""


#: orientation_sigma.csv's columns: the 1-sigma uncertainty [deg] of each frame's absolute
#: orientation R_w_c, along its worst axis and about the camera's x, y, z (right perturbation,
#: BackendResult.covariance), as the chain propagates it and as the backend estimates it.
ORIENTATION_SIGMA_FIELDS = (
    "index",
    "t",
    "chain_sigma_deg",
    "chain_sigma_x_deg",
    "chain_sigma_y_deg",
    "chain_sigma_z_deg",
    "backend_sigma_deg",
    "backend_sigma_x_deg",
    "backend_sigma_y_deg",
    "backend_sigma_z_deg",
)


def format_orientation_sigma(
    t: np.ndarray, chain: np.ndarray | None, backend: np.ndarray | None, origin_ns: int = 0
) -> str:
    """orientation_sigma.csv: a header (ORIENTATION_SIGMA_FIELDS), then per frame its index, time
    (clock_time) and the sigmas [deg] of the covariances [rad^2] (N, 3, 3) `chain` and `backend`
    (empty fields for one that is None)."""

    def columns(covariance: np.ndarray | None) -> list[list[str]]:
        if covariance is None:
            return [[""] * 4 for _ in t]
        sigmas = np.degrees(np.column_stack([largest_sigma(covariance), axis_sigmas(covariance)]))
        return [[f"{v:.6f}" for v in row] for row in sigmas]

    rows = [",".join(ORIENTATION_SIGMA_FIELDS)]
    for k, (a, b) in enumerate(zip(columns(chain), columns(backend))):
        rows.append(",".join([str(k), clock_time(t[k], origin_ns), *a, *b]))
    return "\n".join(rows) + "\n"


def write_outputs(out: Path, result: RunResult, label: str, origin: str = "") -> None:
    """trajectory.tum, groundtruth.tum, orientation_sigma.csv, metrics.json and rotation.png
    (each written atomically); `label` names the dataset and `origin` the configuration
    (ResolvedConfig.origin) in its title."""
    zeros = np.zeros((len(result.t), 3))
    origin_ns = result.clock_origin_ns
    write_text_atomic(out / "trajectory.tum", format_tum(result.t, zeros, result.R_w_c, origin_ns))
    write_text_atomic(
        out / "orientation_sigma.csv",
        format_orientation_sigma(result.t, result.chain_covariance, result.covariance, origin_ns),
    )
    if result.causal_R_w_c is not None:
        write_text_atomic(out / "trajectory_causal.tum", format_tum(result.t, zeros, result.causal_R_w_c, origin_ns))
    errors = result.errors
    if errors is not None and errors.valid.any():
        write_text_atomic(
            out / "groundtruth.tum", format_tum(result.t[errors.valid], errors.p_w_c_gt, errors.R_w_c_gt, origin_ns)
        )
    write_text_atomic(out / "metrics.json", json_text(result.metrics))
    from eas_vo.plots import plot_rotation

    with atomic_path(out / "rotation.png") as tmp:
        m = result.metrics
        plot_rotation(
            tmp, result, title=f"{m['frontend']} + {m['tracker']} + {m['backend']} ({origin or 'defaults'}): {label}"
        )
