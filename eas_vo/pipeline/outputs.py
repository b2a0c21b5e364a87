"""What a run produced (`RunResult`) and its files: trajectory.tum, groundtruth.tum, metrics.json
and rotation.png."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eas_vo.evaluation.ape import RotationErrors
from eas_vo.io.atomic import atomic_path, json_text, write_text_atomic
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


RUN_FILES = ("config.toml", "identity.json", "frames.csv", "trajectory.tum", "metrics.json", "rotation.png")
"""What every finished run's folder holds (groundtruth.tum and trajectory_causal.tum when they apply)."""


def write_outputs(out: Path, result: RunResult, label: str, origin: str = "") -> None:
    """trajectory.tum, groundtruth.tum, metrics.json and rotation.png (each written atomically);
    `label` names the dataset and `origin` the configuration (ResolvedConfig.origin) in its title."""
    zeros = np.zeros((len(result.t), 3))
    origin_ns = result.clock_origin_ns
    write_text_atomic(out / "trajectory.tum", format_tum(result.t, zeros, result.R_w_c, origin_ns))
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
