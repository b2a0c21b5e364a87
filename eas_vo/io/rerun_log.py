"""Rerun recordings (`.rrd`, https://rerun.io) of a run, written with rerun-sdk (the `view`
extra), which only this module imports, when a recording is made: eas-vo runs without it.

Entities, on the timelines `t` (the frame's time [s], as the run's files write it) and `frame`
(its index in the run); docs/outputs.md#looking-at-a-run describes them for the user:

    image                          the frontend's image of the frame (uint8, sensor size)
    image/inliers, image/outliers  the tracked points [px] its rotation's model counts as inliers, or not
    status                         the frame's status and reason (a text log: weak a warning, lost an error)
    world/estimate, world/truth    R_w_c as a 3D frame (x red, y green, z blue: the optical axis)
    euler/{roll,pitch,yaw}/{estimate,truth}   Euler angles (z-y-x) [deg]
    error/ape_deg                  the rotation error against the ground truth [deg]
    error/predicted_deg            the error the backend's covariance predicts (its RMS) [deg]
    tracking/nc, tracking/inliers  correspondences and inliers per frame
    events                         one window of events as points in x, y and time (static)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eas_vo.errors import EasVoError
from eas_vo.geometry.rotations import euler_zyx_deg

#: Rerun's application id of every eas-vo recording (the viewer groups recordings by it).
APPLICATION_ID = "eas-vo"
#: The Euler angles in the order geometry.rotations.euler_zyx_deg gives them.
EULER = ("roll", "pitch", "yaw")
#: Colours (RGB): inlier and outlier points, events by polarity.
INLIER_RGB, OUTLIER_RGB = (40, 200, 40), (230, 50, 50)
ON_RGB, OFF_RGB = (60, 120, 255), (255, 80, 60)
#: How an orientation is drawn: its curves' colour (RGB) and its 3D frame's axis length (the
#: truth's shorter, so that the estimate's shows beside it).
STYLES = {"estimate": ((230, 120, 20), 1.0), "truth": ((90, 90, 90), 0.8)}
#: A frame's status as a text log's level.
STATUS_LEVELS = {"first": "INFO", "ok": "INFO", "weak": "WARN", "lost": "ERROR", "same_time": "DEBUG"}


def rerun_sdk():
    """The `rerun` module, or a one-line error saying how to install it."""
    try:
        import rerun
    except ImportError:
        raise EasVoError('the viewer needs rerun-sdk: pip install "eas-vo[view]"') from None
    return rerun


def viewer_url() -> str:
    """Rerun's web viewer of the installed rerun-sdk's version (a recording opens in the same version)."""
    return f"https://app.rerun.io/version/{rerun_sdk().__version__}"


class RerunLog:
    """A recording written to `path` as it is logged; `close` ends the file."""

    def __init__(self, path: str | Path, name: str):
        """Start the recording `name` (shown by the viewer) in the file `path`, with eas-vo's layout."""
        self.rr = rr = rerun_sdk()
        self.rec = rr.RecordingStream(APPLICATION_ID)
        self.rec.save(str(path), default_blueprint=_blueprint())
        self.rec.send_recording_name(name)

    def frame(self, k: int, t_s: float, image: np.ndarray | None, points: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Frame `k` at `t_s` [s]: its image (uint8 (H, W); None: the frontend makes none) and
        tracked points ((N, 2) positions [px], (N,) inlier mask; None: the tracker has none)."""
        rr = self.rr
        self.rec.set_time("frame", sequence=k)
        self.rec.set_time("t", duration=t_s)
        if image is not None:
            self.rec.log("image", rr.Image(image, color_model="L"))
        if points is not None:
            px, inlier = points
            px = np.asarray(px, float) + 0.5  # OpenCV's pixel centres are whole; Rerun's image starts at a corner
            self.rec.log("image/inliers", rr.Points2D(px[inlier], colors=[INLIER_RGB]))
            self.rec.log("image/outliers", rr.Points2D(px[~inlier], colors=[OUTLIER_RGB]))

    def statuses(self, frames: np.ndarray, t_s: np.ndarray, status: list[str], reason: list[str]) -> None:
        """Each frame's `status` and `reason` (frames.csv's) as a text log."""
        text = [f"{s}: {r}" if r else s for s, r in zip(status, reason)]
        levels = [STATUS_LEVELS.get(s, "INFO") for s in status]
        self._columns("status", frames, t_s, self.rr.TextLog.columns(text=text, level=levels))

    def orientations(self, who: str, frames: np.ndarray, t_s: np.ndarray, R_w_c: np.ndarray) -> None:
        """Camera-to-world rotations (N, 3, 3) of `who` ("estimate" or "truth") at `frames` and
        `t_s` [s]: as world/WHO's 3D frame and as Euler angles [deg], unwrapped over time."""
        rr = self.rr
        rgb, axis_length = STYLES[who]
        self.rec.log(f"world/{who}", rr.TransformAxes3D(axis_length), static=True)
        self._columns(f"world/{who}", frames, t_s, rr.Transform3D.columns(mat3x3=R_w_c))
        angles = np.unwrap(euler_zyx_deg(R_w_c), period=360, axis=0)
        for angle, values in zip(EULER, angles.T):
            self.rec.log(f"euler/{angle}/{who}", rr.SeriesLines(colors=[rgb], names=[who]), static=True)
            self.series(f"euler/{angle}/{who}", frames, t_s, values)

    def series(self, entity: str, frames: np.ndarray, t_s: np.ndarray, values: np.ndarray) -> None:
        """A scalar curve: `values` (N,) at `frames` and `t_s` [s]."""
        self._columns(entity, frames, t_s, self.rr.Scalars.columns(scalars=np.asarray(values, float)))

    def events(self, events: np.ndarray, t0_s: float, t1_s: float, width_px: int) -> None:
        """Events (EVENT_DTYPE) of [t0_s, t1_s) [s] as points (x, y, time), time stretched so that
        the window spans `width_px`; on events blue, off events red (static)."""
        z = (events["t"] - t0_s) / (t1_s - t0_s) * width_px
        xyz = np.column_stack([events["x"] + 0.5, events["y"] + 0.5, z])
        colours = np.where((events["p"] > 0)[:, None], ON_RGB, OFF_RGB).astype(np.uint8)
        self.rec.log("events", self.rr.Points3D(xyz, colors=colours), static=True)

    def close(self) -> None:
        """Write what is pending and end the file."""
        self.rec.flush()
        self.rec.disconnect()

    def _columns(self, entity: str, frames: np.ndarray, t_s: np.ndarray, columns) -> None:
        rr = self.rr
        indexes = [rr.TimeColumn("frame", sequence=frames), rr.TimeColumn("t", duration=t_s)]
        self.rec.send_columns(entity, indexes=indexes, columns=columns)


def _blueprint():
    """The viewer's layout: image and status; orientations and events in 3D; the curves."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(origin="image", name="image and tracked points"),
                rrb.TextLogView(origin="status", name="status"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="orientation (R_w_c)"),
                rrb.Spatial3DView(origin="events", name="events (x, y, t)"),
            ),
            rrb.Vertical(
                *(rrb.TimeSeriesView(origin=f"euler/{angle}", name=f"{angle} [deg]") for angle in EULER),
                rrb.TimeSeriesView(origin="error", name="error [deg]"),
                rrb.TimeSeriesView(origin="tracking", name="correspondences"),
            ),
        ),
    )


def open_in_viewer(path: str | Path) -> None:
    """Open the recording `path` in Rerun's viewer, a window of its own (the process is left running)."""
    import subprocess
    import sys

    rerun_sdk()
    subprocess.Popen([sys.executable, "-m", "rerun_cli", str(path)], start_new_session=True)
