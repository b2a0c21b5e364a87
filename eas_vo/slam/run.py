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
import importlib.util
import io
import multiprocessing
import os
import signal
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError, EasVoError, Interrupted
from eas_vo.io.atomic import json_text, write_text_atomic
from eas_vo.io.outputs import output_folder
from eas_vo.io.text import figure_text

EXTRA_HINT = "monocular ORB-SLAM3 runs through the optional extra: pip install 'eas-vo[slam]' (pyorbslam3, GPL-3.0)"
FRAMES_FIELDS = ("index", "t", "state", "tracked_points", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
#: States in which ORB-SLAM3 tracked the frame against its map.
TRACKED = ("ok", "relocalised")
#: A run is `ok` when ORB-SLAM3 tracked at least this share of the frames from its first
#: initialisation on, the last frame among them; else `lost` (or `never_initialised`).
MIN_TRACKED_FRACTION = 0.9
#: What makes a run's figures comparable: the pacing (slam.worker) and the status rule.
#: reproduce's Table 2 reuses a cell's runs only when they were made under this protocol.
PROTOCOL = f"paced by mapping idle; ok: >= {MIN_TRACKED_FRACTION:.0%} tracked after init and the last frame"
#: How often [s] the parent looks whether a silent child is still alive.
POLL_S = 0.5


class SlamCrashed(EasVoError):
    """ORB-SLAM3's process ended without being asked to."""


def require_extra() -> None:
    """One line naming the extra when pyorbslam3 is not installed (checked without importing it)."""
    if importlib.util.find_spec("pyorbslam3") is None:
        raise EasVoError(f"pyorbslam3 is not installed: {EXTRA_HINT}")


def find_vocabulary(given: str | None) -> Path:
    """The vocabulary to load: `given`, else $PYORBSLAM3_VOCAB, else ORBvoc.txt in the data
    folder; every line of it and its tree checked (vocabulary.check_vocabulary) before ORB-SLAM3
    loads it. One line when there is none, or it is broken."""
    from eas_vo.datasets.ecd_catalogue import data_dir
    from eas_vo.slam.orbvoc import NAME
    from eas_vo.slam.vocabulary import check_vocabulary

    if given is None:
        given = os.environ.get("PYORBSLAM3_VOCAB") or None
    path = Path(given).expanduser() if given else data_dir() / NAME
    if not path.is_file():
        if given:
            raise DataError(path, "no such vocabulary file")
        raise EasVoError(
            f"no ORB vocabulary: give --vocabulary FILE (one `eas-vo vocabulary` trains), set "
            f"PYORBSLAM3_VOCAB, or download ORB-SLAM3's with `eas-vo fetch orb-vocabulary` (into {path})"
        )
    check_vocabulary(path)
    return path


class OrbSlam3Process:
    """Monocular ORB-SLAM3 in a child process (spawned: no state of this one is inherited)."""

    def __init__(self, vocabulary: Path, settings: Path, log: Path):
        from eas_vo.slam import worker

        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        self.log = log
        self.process = context.Process(
            target=worker.serve, args=(child, str(vocabulary), str(settings), str(log)), daemon=True, name="orbslam3"
        )
        self.process.start()
        child.close()
        answer = self._receive("while loading the vocabulary and settings")
        if answer[0] == "error":
            self.close()
            raise EasVoError(f"ORB-SLAM3 did not start: {answer[1]} (see {log})")

    def track(self, image: np.ndarray, t: float) -> tuple[str, int, np.ndarray | None]:
        """(state, tracked map points, T_w_c or None) of one frame."""
        self._send(("frame", np.ascontiguousarray(image), float(t)), "while tracking")
        return self._receive("while tracking")[1:]

    def finish(self, keyframes: Path, frames: Path | None) -> None:
        """Shut ORB-SLAM3 down and have it save both trajectories (`frames` None: only the keyframes)."""
        self._send(("finish", str(keyframes), str(frames) if frames else None), "while saving")
        self._receive("while shutting down and saving its trajectories")
        self.process.join(timeout=30)

    def close(self) -> None:
        """End the child if it still runs (after an error or an interrupt)."""
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5)
            if self.process.is_alive():
                self.process.kill()
                self.process.join()
        self._conn.close()

    def _send(self, message, doing: str) -> None:
        try:
            self._conn.send(message)
        except (BrokenPipeError, ConnectionResetError, EOFError):
            raise self._crashed(doing) from None

    def _receive(self, doing: str):
        while not self._conn.poll(POLL_S):
            if not self.process.is_alive():
                raise self._crashed(doing)
        try:
            return self._conn.recv()
        except (EOFError, ConnectionResetError):
            raise self._crashed(doing) from None

    def _crashed(self, doing: str) -> SlamCrashed:
        self.process.join(timeout=5)
        code = self.process.exitcode
        if code is not None and code < 0:
            how = f"was killed by signal {-code} ({signal.Signals(-code).name})"
        else:
            how = f"exited with status {code}"
        return SlamCrashed(f"ORB-SLAM3's process {how} {doing} (its output: {self.log})")


@dataclass
class FrameResult:
    """One frame of an ORB-SLAM3 run: its index, time [s], tracking state, tracked map points and
    the pose ORB-SLAM3 gave then (camera-to-world, 4x4, its map's frame; None while not tracking)."""

    index: int
    t: float
    state: str
    tracked_points: int
    T_w_c: np.ndarray | None


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


def relabel(states: list[str]) -> list[str]:
    """ORB-SLAM3's states with `relocalised` for an `ok` frame right after a lost one in the
    same map (it found its map again; an `ok` after `not_initialised` is a new initialisation)."""
    out, previous = [], "not_initialised"
    for s in states:
        out.append("relocalised" if s == "ok" and previous in ("recently_lost", "lost") else s)
        previous = s
    return out


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
        _euroc_to_tum(folder / "frames.euroc", folder / "trajectory.tum", results)
    return counts(results)


def counts(results: list[FrameResult]) -> dict:
    """A run's status, time to first initialisation [s], the fractions of frames tracked (of
    all, and of those from the first initialisation on) and the first frame after it that was
    not tracked. Status: `never_initialised` without a tracked frame; `ok` when the frames from
    the first initialisation on were tracked at least MIN_TRACKED_FRACTION of the time and the
    last frame was; else `lost`."""
    states = [r.state for r in results]
    tracked = np.array([s in TRACKED for s in states])
    first = int(np.argmax(tracked)) if tracked.any() else None
    after = tracked[first:] if first is not None else tracked[:0]
    untracked = np.flatnonzero(~after)
    ok = first is not None and after.mean() >= MIN_TRACKED_FRACTION and bool(after[-1])
    return {
        "status": "never_initialised" if first is None else "ok" if ok else "lost",
        "frames": len(states),
        "first_initialised_frame": first,
        "time_to_init_s": results[first].t - results[0].t if first is not None else None,
        "tracked_fraction": float(tracked.mean()) if len(tracked) else 0.0,
        "tracked_fraction_after_init": float(after.mean()) if first is not None else None,
        "first_lost_frame": int(first + untracked[0]) if len(untracked) else None,
        "last_state": states[-1] if states else None,
        "states": {s: states.count(s) for s in sorted(set(states))},
    }


def _euroc_to_tum(src: Path, dst: Path, results: list[FrameResult]) -> None:
    """ORB-SLAM3's EuRoC trajectory (`t_ns tx ty tz qx qy qz qw`) as TUM, then removed: the
    line of each frame of `results` that ORB-SLAM3 tracked, once, at the frame's own time.
    ORB-SLAM3 writes a line per frame since its initialisation, and for a frame it could not
    pose the previous frame's time and pose again (Tracking::Track, "This can happen if
    tracking is lost"), so its file can hold one time twice and poses of frames it lost."""
    from eas_vo.io.tables import read_table

    rows = (
        read_table(src, 8, "ORB-SLAM3 EuRoC pose 't_ns tx ty tz qx qy qz qw'")
        if src.stat().st_size
        else np.empty((0, 8))
    )
    t = np.array([r.t for r in results])
    tracked = np.array([r.state in TRACKED for r in results])
    frame = _frame_of(rows[:, 0] * 1e-9, t)
    keep = frame >= 0
    keep[keep] = tracked[frame[keep]]
    _, first = np.unique(frame[keep], return_index=True)
    rows, frame = rows[keep][first], frame[keep][first]
    write_text_atomic(
        dst, "".join(f"{t[k]:.9f} " + " ".join(f"{v:.9f}" for v in r[1:]) + "\n" for k, r in zip(frame, rows))
    )
    src.unlink()


def on_recording_clock(folder: Path, origin_ns: int) -> None:
    """A run folder's times (ORB-SLAM3 is fed, and its files and frames.csv first hold, times
    after the dataset's clock origin) written as the recording's own: the origin added back in
    integer ns (io.clock_time), as every eas-vo output holds them."""
    from eas_vo.io.tables import clock_time

    if not origin_ns:
        return
    for path in sorted(folder.glob("*.tum")):
        lines = path.read_text().splitlines(keepends=True)
        write_text_atomic(
            path,
            "".join(
                line
                if not line.strip() or line.startswith("#")
                else clock_time(float(line.split(maxsplit=1)[0]), origin_ns) + " " + line.split(maxsplit=1)[1]
                for line in lines
            ),
        )
    frames = folder / "frames.csv"
    if frames.exists():
        rows = list(csv.reader(frames.read_text().splitlines()))
        rows[1:] = [[row[0], clock_time(float(row[1]), origin_ns), *row[2:]] for row in rows[1:]]
        text = io.StringIO()
        csv.writer(text).writerows(rows)  # (the dialect frames.csv is written in)
        write_text_atomic(frames, text.getvalue())


def _frame_of(t_row: np.ndarray, t_frame: np.ndarray) -> np.ndarray:
    """The index of the frame (times `t_frame` [s], increasing) each time of `t_row` [s] is, or
    -1: the nearest frame, within a quarter of the smallest gap between frames (the times went
    through ORB-SLAM3's double and its writer's text)."""
    if not len(t_frame):
        return np.full(len(t_row), -1)
    gaps = np.diff(t_frame)
    tolerance = 0.25 * float(gaps[gaps > 0].min()) if (gaps > 0).any() else np.inf
    right = np.clip(np.searchsorted(t_frame, t_row), 0, len(t_frame) - 1)
    left = np.maximum(right - 1, 0)
    k = np.where(np.abs(t_frame[left] - t_row) <= np.abs(t_frame[right] - t_row), left, right)
    return np.where(np.abs(t_frame[k] - t_row) <= tolerance, k, -1)


def score(ground_truth, path: Path, shown_as: Path, max_diff_s: float = 0.01) -> dict:
    """Sim(3) APE of a TUM trajectory against ground truth, and the trajectory so aligned
    beside it (NAME_aligned.tum, in the ground truth's world); "ape_problem" when it cannot
    be scored: too few poses, poses on a line, times out of order (naming the file `shown_as`)."""
    from eas_vo.evaluation.trajectory import trajectory_ape
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import format_tum, read_tum

    if not path.exists() or not path.stat().st_size:
        return {"ape_problem": "no poses"}
    try:
        estimate = read_tum(path)
        ape = trajectory_ape(ground_truth, estimate, "sim3", max_diff_s)
    except (ValueError, EasVoError) as exc:
        return {"ape_problem": str(exc).replace(str(path), str(shown_as))}
    aligned = ape.aligned(estimate.p_w_c, matrices_from_quats(estimate.q_w_c))
    write_text_atomic(path.with_name(f"{path.stem}_aligned.tum"), format_tum(estimate.t, *aligned))
    return ape.summary()


def rotation_score(ground_truth, path: Path, time_offset_s: float) -> dict | None:
    """eas-vo's own rotation APE (Eq. 3: aligned at the first pose, evaluation.rotation_errors)
    of the rotations of a TUM trajectory (the frames ORB-SLAM3 tracked); None without poses."""
    from eas_vo.evaluation.ape import rotation_errors
    from eas_vo.geometry.rotations import matrices_from_quats
    from eas_vo.io.tum import read_tum

    if not path.exists() or not path.stat().st_size:
        return None
    frames = read_tum(path, ordered=False)
    errors = rotation_errors(frames.t, matrices_from_quats(frames.q_w_c), ground_truth, time_offset_s)
    return {**errors.summary(), "frames": int(len(errors.ape_rad))} if len(errors.ape_rad) else None


#: The figures summarised over runs: (key in a run's metrics, its text in summary.md).
SUMMARISED = (
    ("ape_keyframes.ape_trans_mean_m", "keyframe APE [m]"),
    ("ape_frames.ape_trans_mean_m", "all-frame APE [m]"),
    ("ape_keyframes.ape_rot_mean_rad", "keyframe rotation APE [rad]"),
    ("rotation_eq3.ape_mean_rad", "tracked frames' rotation APE, Eq. 3 [rad]"),
    ("time_to_init_s", "time to first init [s]"),
    ("tracked_fraction", "fraction of frames tracked"),
)


def _value(metrics: dict, key: str):
    for part in key.split("."):
        metrics = metrics.get(part) if isinstance(metrics, dict) else None
    return metrics


def summarise(runs: list[dict]) -> dict:
    """Median, min and max of each SUMMARISED figure over the runs whose status is ok; the
    count of each status."""
    good = [m for m in runs if m["status"] == "ok"]
    out = {
        "runs": len(runs),
        "protocol": PROTOCOL,
        "statuses": {s: sum(m["status"] == s for m in runs) for s in sorted({m["status"] for m in runs})},
    }
    for key, _ in SUMMARISED:
        values = [v for m in good if (v := _value(m, key)) is not None]
        out[key] = (
            {
                "median": float(np.median(values)),
                "min": float(np.min(values)),
                "max": float(np.max(values)),
                "n": len(values),
            }
            if values
            else None
        )
    return out


def summary_markdown(label: str, frontend: str, summary: dict, orb: dict) -> str:
    """summary.md: the runs' statuses and each figure's median, min and max over the runs, with the
    ORB statistics of the images (`orb`)."""
    lines = [
        f"# ORB-SLAM3 (monocular) on {frontend} images of {label}",
        "",
        f"{summary['runs']} run(s): " + ", ".join(f"{n} {s}" for s, n in summary["statuses"].items()),
        "",
        "| figure | median | min | max | runs |",
        "|---|---|---|---|---|",
    ]
    for key, text in SUMMARISED:
        s = summary[key]
        lines.append(
            f"| {text} | "
            + (
                " | ".join(figure_text(s[k], 3) for k in ("median", "min", "max")) + f" | {s['n']} |"
                if s
                else "- | - | - | 0 |"
            )
        )
    lines += [
        f"| ORB features per image | {orb['orb_keypoints_mean']:.0f} | | | |",
        f"| ORB matches per adjacent pair | {orb['orb_matches_mean']:.0f} | | | |",
        "",
        f"Figures over the runs whose status is ok (from its first initialisation on, ORB-SLAM3 tracked at least "
        f"{MIN_TRACKED_FRACTION:.0%} of the frames, the last one among them); the others are counted, not scored. "
        "APE after Sim(3) Umeyama alignment (evo_ape -as).",
        "",
    ]
    return "\n".join(lines)


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
