"""The ORB-SLAM2 path of the paper (§4.3): image sequences and camera settings a monocular
ORB-SLAM2 / ORB-SLAM3 run reads.

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

from eas_vo.camera import LENS_MODELS, CameraModel
from eas_vo.errors import EasVoError
from eas_vo.io.atomic import write_text_atomic
from eas_vo.io.outputs import output_folder

FORMATS = ("tum", "euroc")


#: ORB-SLAM2's own defaults for its ORB extractor and viewer (its TUM1.yaml).
ORB_EXTRACTOR = {"nFeatures": 1000, "scaleFactor": 1.2, "nLevels": 8, "iniThFAST": 20, "minThFAST": 7}


VIEWER = {
    "KeyFrameSize": 0.05,
    "KeyFrameLineWidth": 1,
    "GraphLineWidth": 0.9,
    "PointSize": 2,
    "CameraSize": 0.08,
    "CameraLineWidth": 3,
    "ViewpointX": 0,
    "ViewpointY": -0.7,
    "ViewpointZ": -1.8,
    "ViewpointF": 500,
}


#: ORB-SLAM3's name (`Camera.type`) for each lens model; ORB-SLAM2 ignores the key (its one model
#: is the pinhole one).
ORBSLAM_CAMERA_TYPES = {"radtan": "PinHole", "equidistant": "KannalaBrandt8"}


def settings_yaml(camera: CameraModel, fps: float) -> str:
    """ORB-SLAM2 / ORB-SLAM3 monocular settings (ORB-SLAM3's legacy layout, which ORB-SLAM2
    reads too): the calibration with its lens model, the frame rate, grayscale images. A
    fisheye (`equidistant`) camera is ORB-SLAM3's KannalaBrandt8 with Camera.k1..k4;
    ORB-SLAM2 has no fisheye model."""
    values = {
        "Camera.fx": camera.K[0, 0],
        "Camera.fy": camera.K[1, 1],
        "Camera.cx": camera.K[0, 2],
        "Camera.cy": camera.K[1, 2],
        **{f"Camera.{name}": float(v) for name, v in zip(LENS_MODELS[camera.model], camera.dist)},
        "Camera.width": camera.width,
        "Camera.height": camera.height,
        "Camera.fps": fps,
        "Camera.RGB": 0,  # the images are grayscale; ORB-SLAM2 reads the flag, not the channel order
        **{f"ORBextractor.{k}": v for k, v in ORB_EXTRACTOR.items()},
        **{f"Viewer.{k}": v for k, v in VIEWER.items()},
    }
    lines = [
        "%YAML:1.0",
        "# written by eas-vo export: monocular ORB-SLAM2 / ORB-SLAM3 settings for this sequence",
        f'Camera.type: "{ORBSLAM_CAMERA_TYPES[camera.model]}"',
    ]
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

    from eas_vo.pipeline import open_pipeline
    from eas_vo.pipeline.tracking import check_image

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
        for sample, name in tqdm(
            zip(parts.dataset.samples(rc.start_s, rc.duration_s), names),
            total=len(window),
            disable=not progress,
            unit="frame",
            desc=f"export {rc.frontend}",
        ):
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
            write_text_atomic(
                staging / "mav0/cam0/data.csv",
                "#timestamp [ns],filename\n" + "".join(f"{_ns(v)},{_ns(v)}.png\n" for v in t),
            )
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
            raise EasVoError(
                f"{label}: frames {first_of[name]} and {k} have one timestamp in the {fmt} layout "
                f"({name[:-4]}); ORB-SLAM2 needs one time per image: export a window without them "
                "(--start, --duration) or fix the dataset's times"
            )
        first_of[name] = int(k)
    return names
