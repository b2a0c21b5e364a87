"""The Python API for notebooks and scripts, exported by `eas_vo` (docs/python.md): `run` (a run as
`eas-vo run` makes it, its results in memory), `open_dataset`, `frontend` and `evaluate` (as
`eas-vo evaluate` scores a trajectory).

Conventions as everywhere in eas-vo: times in seconds on the recording's clock, relative to its
origin (Dataset.clock_origin_ns; files add it back); rotations camera-to-world (`R_w_c`, mapping
camera-frame vectors into the world frame) as (N, 3, 3) matrices. Errors the user can fix raise
`eas_vo.errors.EasVoError` (ConfigError for a bad setting), with the message the command line prints.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo import config as config_mod
from eas_vo import pipeline, registry
from eas_vo.camera import CameraModel
from eas_vo.errors import ConfigError
from eas_vo.experiments.external import evaluate_estimate, evaluate_protocol
from eas_vo.geometry.rotations import quats_from_matrices
from eas_vo.io.outputs import check_output_folder
from eas_vo.pipeline.tracking import frame_table
from eas_vo.plugins import Dataset, Frontend
from eas_vo.types import PoseSeries

#: How a keyword of `run` names a `--set` key: `tracker__max_corners=300` is
#: `--set tracker.max_corners=300`, `tracker__klt__threshold2=150` `--set tracker.klt.threshold2=150`.
KEY_SEPARATOR = "__"


@dataclass(frozen=True, eq=False)
class RunResult:
    """What `run` produced, in memory (the same figures as the files it writes with `out`).

    Attributes:
        times: (N,) the processed frames' times [s] on the recording's clock, from its origin.
        rotations: (N, 3, 3) the estimated camera-to-world rotations R_w_c, frame 0 at the identity.
        ground_truth: (N, 3, 3) the ground truth's R_w_c at each frame's time (plus the run's time
            offset), in the ground truth's own world frame; NaN for the frames it does not score
            (outside its span or in a gap); None for a dataset without ground truth.
        ape_rad: (N,) each frame's rotation error [rad] (the paper's Eq. 3: the estimate aligned to
            the ground truth at the first scored frame); NaN where not scored; None without ground truth.
        frames: frames.csv as a numpy record array, one row a frame (`frames.status`,
            `frames["nc"]`, ...; docs/outputs.md): `t` as `times`, sigmas [deg] NaN where the file's are empty.
        metrics: metrics.json's content (`ape_mean_rad`, `nc_mean`, `status_counts`, ...).
        config: the resolved configuration (`config.to_toml()` is config.toml).
        folder: the folder the files were written to; None when `run` was given no `out`.
    """

    times: np.ndarray
    rotations: np.ndarray
    ground_truth: np.ndarray | None
    ape_rad: np.ndarray | None
    frames: np.recarray
    metrics: dict
    config: config_mod.ResolvedConfig
    folder: Path | None


def run(
    dataset: str | None = None,
    config: str | Path | None = None,
    *,
    frontend: str | None = None,
    tracker: str | None = None,
    backend: str | None = None,
    out: str | Path | None = None,
    **sets,
) -> RunResult:
    """Run a frontend, tracker and backend on a dataset, as `eas-vo run` does.

    Args:
        dataset: `PLUGIN:LOCATION` or a location a dataset plugin recognises (None: the config's,
            else `synthetic:default`, the embedded 10 s sequence, simulated once and cached).
        config: a TOML config file or a bundled config's name (`paper`, `best`); None: defaults.
        frontend, tracker, backend: plugin names (None: the config's, else eas, klt, chain).
        out: a new (or empty) folder to write the run's files into (docs/outputs.md); None: no files.
        **sets: config overrides, `SECTION__KEY=value` for `--set SECTION.KEY=value`
            (`tracker__max_corners=300`, `run__duration_s=2.0`, `frontend__eas__n=8000`).

    Returns:
        The RunResult.
    """
    assignments = [config_mod.assignment(_dotted(key), _plain(value)) for key, value in sets.items()]
    resolved = config_mod.resolve(
        config, {"dataset": dataset, "frontend": frontend, "tracker": tracker, "backend": backend}, assignments
    )
    folder = None if out is None else check_output_folder(out, replace=False)
    result = pipeline.run(resolved, folder)
    errors = result.errors
    return RunResult(
        times=result.t,
        rotations=result.R_w_c,
        ground_truth=None if errors is None else _per_frame(errors.valid, errors.R_w_c_gt),
        ape_rad=None if errors is None else _per_frame(errors.valid, errors.ape_rad),
        frames=frame_table(result.records, result.edges),
        metrics=result.metrics,
        config=resolved,
        folder=folder,
    )


def open_dataset(spec: str = "synthetic:default", **settings) -> Dataset:
    """Open a dataset as `--dataset SPEC` does, with its plugin's settings (`eas-vo list` shows
    them; e.g. `lenient=True`).

    Its `camera`, `ground_truth` (camera-to-world poses) and `imu` are attributes;
    `samples(start_s=0, duration_s=inf)` yields its Samples in time order: `t` [s], `frame` (uint8
    (H, W), None for an event-only stream), `events_after` and `events_since_previous` (views of
    the event array: `t` [s], `x`, `y` [px], `p`).
    """
    cls, _ = registry.resolve_dataset(spec)
    return registry.open_dataset(spec, _settings(cls, "dataset", settings))


def frontend(name: str, camera: CameraModel, **params) -> Frontend:
    """The frontend plugin `name` for `camera` (a dataset's `camera`), with its config keys as
    keywords (e.g. `n=8000` for eas). Call it on each sample in time order:
    `frontend(sample)` is the sample's uint8 image (camera.height, camera.width); `reset()`
    forgets the samples seen (stateful frontends consume the events since the previous one)."""
    cls = registry.get("frontends", name)
    return cls(_settings(cls, "frontend", params), camera)


def evaluate(
    estimate: RunResult | tuple[np.ndarray, np.ndarray] | PoseSeries | str | Path,
    dataset: str | Dataset,
    *,
    protocol: str = "evo",
    align: str | None = None,
    max_diff_s: float | None = None,
) -> dict:
    """Score a trajectory against a dataset's ground truth, as `eas-vo evaluate` does.

    Args:
        estimate: a RunResult; (times [s], R_w_c (N, 3, 3)) or a PoseSeries, both on the
            dataset's clock (as a run's times); or a TUM file (`t tx ty tz qx qy qz qw`, on the
            recording's own clock, as eas-vo and other tools write them).
        dataset: the dataset it was made on: a `--dataset` value or an opened dataset.
        protocol: `evo` (evo_ape's APE) or `cmax-slam` (the event-rotation benchmark's:
            docs/rotation_benchmark.md).
        align: evo only: `origin` (default: the first poses made equal, for rotation-only
            trajectories such as eas-vo's), `sim3` or `se3` (Umeyama, for 6-DoF SLAM output).
        max_diff_s: evo only: the largest time difference of an associated pose pair [s] (default 0.01).

    Returns:
        The metrics `eas-vo evaluate` writes to metrics.json: for evo `ape_rot_mean_rad`,
        `ape_rot_rmse_rad`, `ape_trans_mean_m`, `matched_poses`, ...; for cmax-slam
        `absolute_rms_deg`, `relative_rms_deg_s`, ...
    """
    poses = _poses(estimate)
    if protocol == "cmax-slam":
        if align is not None or max_diff_s is not None:
            raise ConfigError(
                "align and max_diff_s are the evo protocol's; cmax-slam aligns and scores by its own rules"
            )
        return evaluate_protocol(dataset, poses)
    if protocol != "evo":
        raise ConfigError(f"protocol {protocol!r}: choose evo or cmax-slam")
    return evaluate_estimate(dataset, poses, align or "origin", 0.01 if max_diff_s is None else max_diff_s)


def _dotted(key: str) -> str:
    """A keyword of `run`'s `sets` as `--set` spells it: `tracker__max_corners` -> `tracker.max_corners`."""
    if KEY_SEPARATOR not in key:
        raise ConfigError(
            f"{key}: name a config key as SECTION{KEY_SEPARATOR}KEY (e.g. tracker{KEY_SEPARATOR}{key}), "
            f"SECTION one of {', '.join(config_mod.SECTIONS)}"
        )
    return key.replace(KEY_SEPARATOR, ".")


def _plain(value):
    """A numpy scalar or array as the Python value a config holds (np.int64(3) -> 3)."""
    return value.tolist() if isinstance(value, (np.generic, np.ndarray)) else value


def _settings(cls: type, section: str, values: dict):
    """The plugin `cls`'s Config from `values`, checked as a config file's `[section]` is."""
    plain = {key: _plain(value) for key, value in values.items()}
    return config_mod.build(cls.Config, plain, f"{section}.{cls.name}")


def _per_frame(valid: np.ndarray, values: np.ndarray) -> np.ndarray:
    """`values` of the frames where `valid` is true, spread to every frame with NaN between."""
    full = np.full((len(valid), *values.shape[1:]), np.nan)
    full[valid] = values
    return full


def _poses(estimate) -> PoseSeries | str | Path:
    """`evaluate`'s estimate as experiments.external takes it: a TUM file, or poses in memory
    (rotations as quaternions, positions 0 for a rotation-only trajectory)."""
    if isinstance(estimate, (PoseSeries, str, Path)):
        return estimate
    t, R_w_c = (estimate.times, estimate.rotations) if isinstance(estimate, RunResult) else estimate
    t, R_w_c = np.asarray(t, float), np.asarray(R_w_c, float)
    return PoseSeries(t, np.zeros((len(t), 3)), quats_from_matrices(R_w_c))
