"""`eas-vo slam`: a frontend's images, frame by frame, into monocular ORB-SLAM3 (in a child
process: slam.worker), scored as the paper's Table 2 scores ORB-SLAM2.

OUT/run_R/ (one per run, R = 1..N):
    settings.yaml   ORB-SLAM3's settings (the dataset's calibration, as `export` writes them)
    frames.csv      per frame: index, t [s], tracking state, tracked map points, the pose ORB-SLAM3
                    gave when it tracked the frame (camera-to-world, its map's frame, up to scale;
                    empty for a frame it did not track)
    keyframes.tum   the keyframe trajectory (ORB-SLAM3's SaveKeyFrameTrajectoryTUM)
    trajectory.tum  each frame ORB-SLAM3 tracked (TRACKED), once, at its own time, posed after
                    the final optimisation (SaveTrajectoryEuRoC, written as TUM; frames it did not
                    track have no line); absent when it never initialised or its map was reset
                    (a lost track) and holds no keyframe
    keyframes_aligned.tum, trajectory_aligned.tum   both after the Sim(3) alignment, in the
                    ground truth's world (when they could be scored)
    metrics.json    status, time to first initialisation, fractions tracked, Sim(3) APE of both,
                    and eas-vo's own rotation APE (Eq. 3) of the tracked frames
    slam.log        what ORB-SLAM3 printed
OUT/summary.json, OUT/summary.md: the median and the spread over the runs that tracked, and the
ORB features and matches of the images as Table 2 counts them.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from eas_vo.errors import Interrupted
from eas_vo.io.atomic import json_text, write_text_atomic
from eas_vo.io.outputs import output_folder
from eas_vo.slam.process import FrameResult, OrbSlam3Process, SlamCrashed, find_vocabulary, relabel, require_extra
from eas_vo.slam.scores import (
    TRACKED,
    counts,
    euroc_to_tum,
    on_recording_clock,
    rotation_score,
    score,
    summarise,
    summary_markdown,
)

FRAMES_FIELDS = ("index", "t", "state", "tracked_points", "tx", "ty", "tz", "qx", "qy", "qz", "qw")


def _frames_row(r: FrameResult) -> list:
    from eas_vo.geometry.rotations import quats_from_matrices

    if r.T_w_c is None:
        return [r.index, f"{r.t:.9f}", r.state, r.tracked_points] + [""] * 7
    q = quats_from_matrices(r.T_w_c[None, :3, :3])[0]
    return [
        r.index,
        f"{r.t:.9f}",
        r.state,
        r.tracked_points,
        *(f"{v:.9f}" for v in r.T_w_c[:3, 3]),
        *(f"{v:.12f}" for v in q),
    ]


def track_sequence(images, times, vocabulary: Path, settings: Path, folder: Path, progress: bool, label: str) -> dict:
    """One run: every image to ORB-SLAM3, frames.csv written as it goes, both trajectories
    saved; returns the run's counts. A crash of ORB-SLAM3 leaves frames.csv with the frames done
    and raises SlamCrashed (its message says how many)."""
    from tqdm import tqdm

    results: list[FrameResult] = []
    slam = OrbSlam3Process(vocabulary, settings, folder / "slam.log")
    try:
        with open(folder / "frames.csv", "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(FRAMES_FIELDS)
            previous = "not_initialised"
            try:
                for k, (image, t) in enumerate(
                    tqdm(zip(images, times), total=len(times), disable=not progress, unit="frame", desc=label)
                ):
                    state, points, pose = slam.track(image, t)
                    shown = relabel([previous, state])[1]
                    r = FrameResult(k, float(t), shown, points, pose if shown in TRACKED else None)
                    previous = state
                    results.append(r)
                    writer.writerow(_frames_row(r))
                    fh.flush()
            except SlamCrashed as exc:
                raise SlamCrashed(
                    f"{exc}; at frame {len(results)} of {len(times)}: {folder / 'frames.csv'} keeps "
                    f"the {len(results)} frame(s) done"
                ) from None
        initialised = any(r.state in TRACKED for r in results)
        slam.finish(folder / "keyframes.tum", folder / "frames.euroc" if initialised else None)
    finally:
        slam.close()
    if (folder / "frames.euroc").exists():
        euroc_to_tum(folder / "frames.euroc", folder / "trajectory.tum", results)
    return counts(results)


def run_slam(
    config, out: str | Path, vocabulary: str | None = None, runs: int = 5, progress: bool = False, replace: bool = False
) -> dict:
    """`runs` runs of monocular ORB-SLAM3 on the window's frontend images into `out` (module
    docstring). A crashed run is kept (its frames.csv, metrics.json status `crashed`) and named
    in the result's `crashed`; the others go on."""
    from eas_vo.orb import OrbStats
    from eas_vo.pipeline import open_pipeline
    from eas_vo.pipeline.tracking import check_image
    from eas_vo.slam.export import settings_yaml

    require_extra()
    vocabulary = find_vocabulary(vocabulary)
    rc = config.run
    parts = open_pipeline(config)
    dataset = parts.dataset
    images, times = [], []
    orb = OrbStats()
    for sample in dataset.samples(rc.start_s, rc.duration_s):
        image = parts.frontend(sample)
        check_image(image, dataset.camera, rc.frontend, sample)
        images.append(image)
        times.append(sample.t)
        orb.add(image)
    t = np.array(times)
    fps = float((len(t) - 1) / (t[-1] - t[0])) if len(t) > 1 and t[-1] > t[0] else 0.0
    gt = dataset.ground_truth
    results, crashed = [], []
    final = Path(out).expanduser().resolve()
    with output_folder(out, replace) as staging:
        for r in range(1, runs + 1):
            folder = staging / f"run_{r}"
            folder.mkdir()
            write_text_atomic(folder / "settings.yaml", settings_yaml(dataset.camera, fps))
            label = f"slam {rc.frontend} run {r}/{runs}"
            try:
                metrics = track_sequence(images, t, vocabulary, folder / "settings.yaml", folder, progress, label)
            except SlamCrashed as exc:
                message = str(exc).replace(str(staging), str(final))
                metrics = {"status": "crashed", "message": message}
                crashed.append(f"run {r} of {runs}: {message}")
            except KeyboardInterrupt as exc:  # the folder is kept, marked partial by this run's status
                on_recording_clock(folder, dataset.clock_origin_ns)
                write_text_atomic(folder / "metrics.json", json_text({"status": "interrupted", "run": r}))
                raise Interrupted.keeping(
                    exc,
                    f"{final} keeps the runs so far, run {r} marked interrupted (its frames.csv up to the interrupt)",
                ) from None
            if gt is not None and metrics["status"] != "crashed":
                for key, name in (("ape_keyframes", "keyframes.tum"), ("ape_frames", "trajectory.tum")):
                    metrics[key] = score(gt, folder / name, final / folder.name / name)
                metrics["rotation_eq3"] = rotation_score(gt, folder / "trajectory.tum", rc.time_offset_s or 0.0)
            metrics.update(run=r, dataset=dataset.label, frontend=rc.frontend, vocabulary=str(vocabulary))
            on_recording_clock(folder, dataset.clock_origin_ns)
            write_text_atomic(folder / "metrics.json", json_text(metrics))
            results.append(metrics)
        summary = {
            **summarise(results),
            **orb.summary(),
            "dataset": dataset.label,
            "frontend": rc.frontend,
            "frames": len(t),
            "vocabulary": str(vocabulary),
            "has_ground_truth": gt is not None,
        }
        write_text_atomic(staging / "summary.json", json_text({**summary, "per_run": results}))
        write_text_atomic(staging / "summary.md", summary_markdown(dataset.label, rc.frontend, summary, orb.summary()))
    return {**summary, "per_run": results, "crashed": crashed}
