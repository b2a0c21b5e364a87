"""An ORB-SLAM3 run scored as the paper's Table 2 scores ORB-SLAM2: how much it tracked, the Sim(3)
APE of its keyframes and frames, eas-vo's rotation APE, and the summary over runs."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from eas_vo.errors import EasVoError
from eas_vo.io.atomic import write_text_atomic
from eas_vo.io.text import figure_text
from eas_vo.slam.process import FrameResult

#: States in which ORB-SLAM3 tracked the frame against its map.
TRACKED = ("ok", "relocalised")


#: A run is `ok` when ORB-SLAM3 tracked at least this share of the frames from its first
#: initialisation on, the last frame among them; else `lost` (or `never_initialised`).
MIN_TRACKED_FRACTION = 0.9


#: What makes a run's figures comparable: the pacing (slam.worker) and the status rule.
#: reproduce's Table 2 reuses a cell's runs only when they were made under this protocol.
PROTOCOL = f"paced by mapping idle; ok: >= {MIN_TRACKED_FRACTION:.0%} tracked after init and the last frame"


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


def euroc_to_tum(src: Path, dst: Path, results: list[FrameResult]) -> None:
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
