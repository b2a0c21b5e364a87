"""The ORB-SLAM2 path of the paper (§4.3): image sequences and camera settings a monocular
ORB-SLAM2 / ORB-SLAM3 run reads, and the scoring of the trajectories it writes.

Layouts written by `export`:
    tum    rgb.txt (`timestamp rgb/NAME.png`, three comment lines first) and rgb/*.png,
           as the TUM RGB-D sequences that `mono_tum` reads
    euroc  mav0/cam0/data/<t_ns>.png, mav0/cam0/data.csv and timestamps.txt (one t_ns a
           line), as the EuRoC sequences that `mono_euroc` reads
and, with either, settings.yaml in ORB-SLAM2's format (OpenCV FileStorage YAML).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from eas_vo.errors import DataError, EasVoError
from eas_vo.io.atomic import json_text, write_text_atomic
from eas_vo.io.outputs import output_folder
from eas_vo.io.tables import data_line, figure_text, markdown_cell, parse_table
from eas_vo.camera import LENS_MODELS, CameraModel
from eas_vo.types import PoseSeries

FORMATS = ("tum", "euroc")

#: ORB-SLAM2's own defaults for its ORB extractor and viewer (its TUM1.yaml).
ORB_EXTRACTOR = {"nFeatures": 1000, "scaleFactor": 1.2, "nLevels": 8, "iniThFAST": 20, "minThFAST": 7}
VIEWER = {"KeyFrameSize": 0.05, "KeyFrameLineWidth": 1, "GraphLineWidth": 0.9, "PointSize": 2, "CameraSize": 0.08,
          "CameraLineWidth": 3, "ViewpointX": 0, "ViewpointY": -0.7, "ViewpointZ": -1.8, "ViewpointF": 500}


#: ORB-SLAM3's name (`Camera.type`) for each lens model; ORB-SLAM2 ignores the key (its one model
#: is the pinhole one).
ORBSLAM_CAMERA_TYPES = {"radtan": "PinHole", "equidistant": "KannalaBrandt8"}


def settings_yaml(camera: CameraModel, fps: float) -> str:
    """ORB-SLAM2 / ORB-SLAM3 monocular settings (ORB-SLAM3's legacy layout, which ORB-SLAM2
    reads too): the calibration with its lens model, the frame rate, grayscale images. A
    fisheye (`equidistant`) camera is ORB-SLAM3's KannalaBrandt8 with Camera.k1..k4;
    ORB-SLAM2 has no fisheye model."""
    values = {
        "Camera.fx": camera.K[0, 0], "Camera.fy": camera.K[1, 1], "Camera.cx": camera.K[0, 2], "Camera.cy": camera.K[1, 2],
        **{f"Camera.{name}": float(v) for name, v in zip(LENS_MODELS[camera.model], camera.dist)},
        "Camera.width": camera.width, "Camera.height": camera.height, "Camera.fps": fps,
        "Camera.RGB": 0,  # the images are grayscale; ORB-SLAM2 reads the flag, not the channel order
        **{f"ORBextractor.{k}": v for k, v in ORB_EXTRACTOR.items()},
        **{f"Viewer.{k}": v for k, v in VIEWER.items()},
    }
    lines = ["%YAML:1.0", "# written by eas-vo export: monocular ORB-SLAM2 / ORB-SLAM3 settings for this sequence",
             f'Camera.type: "{ORBSLAM_CAMERA_TYPES[camera.model]}"']
    lines += [f"{key}: {_yaml_number(value)}" for key, value in values.items()]
    return "\n".join(lines) + "\n"


def _yaml_number(value) -> str:
    """Integers as integers, reals always with a decimal point (FileStorage then reads a real)."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    text = repr(float(value))
    return text if any(c in text for c in ".en") else text + ".0"


def export(config, out: str | Path, fmt: str, progress: bool = False, replace: bool = False) -> dict:
    """Write the window's frontend images in layout `fmt` and settings.yaml into `out` (one
    writer, moved into place whole; an existing output only if `replace`); returns a summary
    (frames, fps, layout)."""
    from tqdm import tqdm

    from eas_vo.pipeline import check_image, open_pipeline

    if fmt not in FORMATS:
        raise EasVoError(f"--format {fmt!r}: choose one of {', '.join(FORMATS)}")
    rc = config.run
    parts = open_pipeline(config)
    window = parts.dataset.window(rc.start_s, rc.duration_s)
    names = _image_names(parts.dataset.label, window, parts.dataset.frame_times()[window], fmt)
    times = []
    with output_folder(out, replace, keep_partial=False) as staging:
        image_dir = staging / ("rgb" if fmt == "tum" else "mav0/cam0/data")
        image_dir.mkdir(parents=True)
        for sample, name in tqdm(zip(parts.dataset.samples(rc.start_s, rc.duration_s), names), total=len(window),
                                 disable=not progress, unit="frame", desc=f"export {rc.frontend}"):
            image = parts.frontend(sample)
            check_image(image, parts.dataset.camera, rc.frontend, sample)
            if not cv2.imwrite(str(image_dir / name), np.ascontiguousarray(image)):
                raise EasVoError(f"{image_dir / name}: could not write the image")
            times.append(sample.t)
        t = np.array(times)
        fps = float((len(t) - 1) / (t[-1] - t[0])) if len(t) > 1 and t[-1] > t[0] else 0.0
        if fmt == "tum":
            header = f"# {rc.frontend} images of {parts.dataset.label}\n# file: 'rgb.txt' (eas-vo export)\n# timestamp filename\n"
            write_text_atomic(staging / "rgb.txt", header + "".join(f"{v:.6f} rgb/{v:.6f}.png\n" for v in t))
        else:
            write_text_atomic(staging / "mav0/cam0/data.csv",
                              "#timestamp [ns],filename\n" + "".join(f"{_ns(v)},{_ns(v)}.png\n" for v in t))
            write_text_atomic(staging / "timestamps.txt", "".join(f"{_ns(v)}\n" for v in t))
        write_text_atomic(staging / "settings.yaml", settings_yaml(parts.dataset.camera, fps))
    return {"frames": len(t), "fps": fps, "format": fmt, "frontend": rc.frontend, "dataset": parts.dataset.label}


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def _image_names(label: str, frames: np.ndarray, times: np.ndarray, fmt: str) -> list[str]:
    """The image file of each frame (its timestamp: TUM's in us, EuRoC's in ns), or a one-line
    error naming two frames that would share one: ORB-SLAM2 takes each image's time from its
    name (EuRoC) or its rgb.txt line (TUM) and keys its trajectory by it, so two frames at one
    time are one pose twice (and a trajectory `evaluate` refuses)."""
    names = [f"{t:.6f}.png" if fmt == "tum" else f"{_ns(t)}.png" for t in times]
    first_of = {}
    for k, name in zip(frames, names):
        if name in first_of:
            raise EasVoError(f"{label}: frames {first_of[name]} and {k} have one timestamp in the {fmt} layout "
                             f"({name[:-4]}); ORB-SLAM2 needs one time per image: export a window without them "
                             "(--start, --duration) or fix the dataset's times")
        first_of[name] = int(k)
    return names


# ----------------------------------------------------------------------------- scoring external trajectories


def read_estimate(path: str | Path) -> PoseSeries:
    """A TUM trajectory file (`t tx ty tz qx qy qz qw` a line, `#` comments), times increasing,
    quaternions non-zero; errors name the file line."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(path, f"cannot read: {exc.strerror or exc}") from None
    rows = parse_table(data, str(path), 8, "TUM pose 't tx ty tz qx qy qz qw'")
    if len(rows) == 0:
        raise DataError(path, "holds no pose")
    back = np.flatnonzero(np.diff(rows[:, 0]) <= 0)
    if len(back):
        raise DataError(f"{path}:{data_line(data, int(back[0]) + 1)}", "timestamp does not increase")
    zero = np.flatnonzero(np.linalg.norm(rows[:, 4:8], axis=1) < 1e-9)
    if len(zero):
        raise DataError(f"{path}:{data_line(data, int(zero[0]))}", "quaternion is zero")
    return PoseSeries(rows[:, 0], rows[:, 1:4], rows[:, 4:8])


def evaluate_estimate(dataset_spec: str, estimate_path: str | Path, align: str, max_diff_s: float,
                      out: str | Path | None = None, label: str | None = None, replace: bool = False) -> dict:
    """Score an external trajectory against a dataset's ground truth (evaluation.trajectory_ape);
    with `out`, write metrics.json, table2_row.md, groundtruth.tum (what it was compared with)
    and estimate_aligned.tum. Returns the metrics."""
    from eas_vo.datasets.recording import clock_unit_problems, time_source
    from eas_vo.evaluation import ALIGNMENTS, trajectory_ape
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.pipeline import format_tum
    from eas_vo.registry import open_dataset

    if align not in ALIGNMENTS:
        raise EasVoError(f"--align {align!r}: choose one of {', '.join(ALIGNMENTS)}")
    read = read_estimate(estimate_path)
    dataset = open_dataset(dataset_spec)
    gt = dataset.ground_truth
    if gt is None:
        raise EasVoError(f"{dataset.label}: has no ground truth to evaluate against")
    origin_ns = dataset.clock_origin_ns  # the estimate holds the recording's own times, the ground truth is after it
    estimate = PoseSeries(read.t - origin_ns / 1e9, read.p_w_c, read.q_w_c)
    spans = {"estimate": float(np.ptp(estimate.t)), "ground-truth": float(np.ptp(gt.t))}
    clocks = clock_unit_problems(spans, {"estimate": str(estimate_path), "ground-truth": time_source(dataset, "ground-truth")})
    if clocks:
        raise EasVoError(next(iter(clocks.values())))
    try:
        ape = trajectory_ape(gt, estimate, align, max_diff_s)
    except ValueError as exc:
        raise EasVoError(f"{estimate_path}: {exc}") from None
    label = label or Path(estimate_path).stem
    metrics = {"estimate": str(estimate_path), "dataset": dataset.label, "align": align, "max_diff_s": max_diff_s,
               "estimate_poses": len(estimate.t), **ape.summary(), **_coverage(estimate.t, gt.t, ape.summary())}
    if out is not None:
        with output_folder(out, replace) as staging:
            write_text_atomic(staging / "metrics.json", json_text(metrics))
            write_text_atomic(staging / "table2_row.md", table2_row(label, metrics))
            write_text_atomic(staging / "groundtruth.tum", format_tum(gt.t, gt.p_w_c, matrices_from_quats(gt.q_w_c), origin_ns))
            aligned = ape.aligned(estimate.p_w_c, matrices_from_quats(estimate.q_w_c))
            write_text_atomic(staging / "estimate_aligned.tum", format_tum(estimate.t, *aligned, origin_ns))
    return metrics


def _coverage(t_est: np.ndarray, t_gt: np.ndarray, summary: dict) -> dict:
    """How much of an estimate (times `t_est` [s]) its ground truth (`t_gt` [s]) scored:
    matched_fraction (matched_poses / estimate poses), the ground truth's first and last time
    from the estimate's first [s] (ground_truth_span_s), the estimate's span [s], and
    `warnings`: one line below evaluation.MIN_SCORED_FRACTION matched."""
    from eas_vo.evaluation import MIN_SCORED_FRACTION

    matched, n = summary["matched_poses"], len(t_est)
    start, end = float(t_gt[0] - t_est[0]), float(t_gt[-1] - t_est[0])
    span = float(t_est[-1] - t_est[0])
    warnings = []
    if matched < MIN_SCORED_FRACTION * n:
        warnings.append(f"the ground truth scores only {matched} of the estimate's {n} poses ({100 * matched / n:.0f} %, "
                        f"under {100 * MIN_SCORED_FRACTION:.0f} %): it spans {start:.3f} to {end:.3f} s of the estimate's "
                        f"0 to {span:.3f} s; the APE describes those poses only")
    return {"matched_fraction": matched / n, "ground_truth_span_s": [start, end], "estimate_span_s": span,
            "warnings": warnings}


def table2_row(label: str, metrics: dict) -> str:
    """A Markdown row as in the paper's Table 2: source, average (translation) APE [m], with
    RMSE, rotation APE, scale and matched poses beside it."""
    m = metrics
    return ("| source | average APE [m] | RMSE [m] | rotation APE [rad] | scale | poses |\n|---|---|---|---|---|---|\n"
            f"| {markdown_cell(label)} | {figure_text(m['ape_trans_mean_m'], 3)} | {figure_text(m['ape_trans_rmse_m'], 3)} | "
            f"{m['ape_rot_mean_rad']:.3f} | "
            f"{m['scale']:.3g} | {m['matched_poses']} |\n")
