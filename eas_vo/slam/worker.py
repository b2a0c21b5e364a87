"""The child process monocular ORB-SLAM3 runs in (pyorbslam3), and its messages.

ORB-SLAM3's C++ threads can abort or crash the process they run in (an unhandled exception in
its optimiser, a vocabulary it cannot read ends in exit()); in a child of its own such an end
is that child's exit status, which the parent reports, keeping what it was sent so far. The
child imports only the standard library, numpy and pyorbslam3, and writes what ORB-SLAM3 prints
to a log file, not to the user's terminal.

Protocol over a multiprocessing Pipe (parent -> child, then child -> parent):
    (start)                         -> ("ready",) or ("error", text)
    ("frame", image uint8 (H, W), t_s) -> ("tracked", state name, tracked map points, T_w_c (4, 4) or None)
    ("finish", keyframes.tum, frames.euroc or None) -> ("done",) once ORB-SLAM3 is shut down and
                                    the trajectories are saved (None, or a map without keyframes:
                                    the keyframes' only)
"""

from __future__ import annotations

import os
import signal

#: ORB-SLAM3's tracking states (pyorbslam3.TrackingState) by the names frames.csv uses.
STATE_NAMES = {"SYSTEM_NOT_READY": "not_initialised", "NO_IMAGES_YET": "not_initialised",
               "NOT_INITIALIZED": "not_initialised", "OK": "ok", "OK_KLT": "ok", "RECENTLY_LOST": "recently_lost",
               "LOST": "lost"}


def serve(conn, vocabulary: str, settings: str, log_path: str) -> None:
    """The child's main: load ORB-SLAM3 (monocular, no viewer) and answer the parent's messages
    until "finish" or the pipe closes. Ctrl-C is the parent's to handle (it ends the child)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    log = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o666)
    os.dup2(log, 1)
    os.dup2(log, 2)
    try:
        import pyorbslam3

        slam = pyorbslam3.Slam(vocabulary, settings, pyorbslam3.Sensor.MONOCULAR, use_viewer=False)
    except Exception as exc:  # noqa: BLE001 - every failure to start is reported to the parent as text
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready",))
    while True:
        try:
            message = conn.recv()
        except EOFError:  # the parent is gone
            slam.shutdown()
            return
        if message[0] == "frame":
            _, image, t = message
            result = slam.track_monocular(image, t)
            pose = result.pose_wc if result.pose_valid else None
            conn.send(("tracked", STATE_NAMES.get(result.state.name, result.state.name.lower()),
                       int(result.num_tracked_points), pose))
        else:
            _, keyframes, frames = message
            slam.shutdown()
            slam.save_keyframe_trajectory_tum(keyframes)
            with open(keyframes) as fh:
                has_keyframes = any(line.strip() for line in fh)
            # SaveTrajectoryEuRoC dereferences the first keyframe of its map: it crashes before
            # an initialisation, and after a reset emptied the map (a lost track)
            if frames is not None and has_keyframes:
                slam.save_trajectory_euroc(frames)
            conn.send(("done",))
            return
