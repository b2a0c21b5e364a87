"""The child process monocular ORB-SLAM3 runs in (pyorbslam3), and its messages.

ORB-SLAM3's C++ threads can abort or crash the process they run in (an unhandled exception in
its optimiser, a vocabulary it cannot read ends in exit()); in a child of its own such an end
is that child's exit status, which the parent reports, keeping what it was sent so far. The
child imports only the standard library, numpy and pyorbslam3, and writes what ORB-SLAM3 prints
to a log file, not to the user's terminal.

Pacing: ORB-SLAM3 tracks a frame in the calling thread (System::TrackMonocular returns once the
frame is tracked), but maps on threads of its own (local mapping, loop closing, global BA), and
in monocular mode its tracker inserts a keyframe only while local mapping is idle (Tracking::
NeedNewKeyFrame returns false when LocalMapping::AcceptKeyFrames() is false). Fed frames as fast
as they are read, a busy machine starves the mapper and the track is lost for want of
keyframes. ORB-SLAM's offline examples (Examples/Monocular/mono_euroc.cc) sleep to the
sequence's own frame rate, which still loses on a machine too busy to map within a frame
period; pyorbslam3 0.1.1 exposes no mapper state (no AcceptKeyFrames, no stop/idle query that
leaves tracking unchanged). So each frame is answered only once every other thread of this
process is idle (wait_until_idle, from the kernel's per-thread scheduler accounting), which is
when ORB-SLAM3's mapping threads have taken in everything the frame gave them: a run is the
same sequence of tracking and mapping steps whatever else the machine does.

Protocol over a multiprocessing Pipe (parent -> child, then child -> parent):
    (start)                         -> ("ready",) or ("error", text)
    ("frame", image uint8 (H, W), t_s) -> ("tracked", state name, tracked map points, T_w_c (4, 4) or None),
                                    sent once the mapping threads are idle (wait_until_idle)
    ("finish", keyframes.tum, frames.euroc or None) -> ("done",) once ORB-SLAM3 is shut down and
                                    the trajectories are saved (None, or a map without keyframes:
                                    the keyframes' only)
"""

from __future__ import annotations

import os
import signal
import threading
import time

#: ORB-SLAM3's tracking states (pyorbslam3.TrackingState) by the names frames.csv uses.
STATE_NAMES = {
    "SYSTEM_NOT_READY": "not_initialised",
    "NO_IMAGES_YET": "not_initialised",
    "NOT_INITIALIZED": "not_initialised",
    "OK": "ok",
    "OK_KLT": "ok",
    "RECENTLY_LOST": "recently_lost",
    "LOST": "lost",
}

#: The mapping threads count as idle when, over a window this long [s], none of them was
#: runnable (state R) or in uninterruptible sleep (D) at its end and together they ran on a CPU
#: less than IDLE_CPU_SHARE of it. Their idle loops sleep 3 ms (LocalMapping::Run) and 5 ms
#: (LoopClosing::Run) and run microseconds a wake-up, so the window holds several of each.
IDLE_WINDOW_S = 0.02
IDLE_CPU_SHARE = 0.1
IDLE_SAMPLE_S = 0.005


def _threads(caller: int) -> dict[int, tuple[str, int]]:
    """(state letter, on-CPU time [ns]) of each thread of this process but `caller`, from
    /proc/self/task/TID/stat (field 3) and /proc/self/task/TID/schedstat (field 1)."""
    out = {}
    for name in os.listdir("/proc/self/task"):
        tid = int(name)
        if tid == caller:
            continue
        try:
            with open(f"/proc/self/task/{tid}/stat") as fh:
                stat = fh.read()
            with open(f"/proc/self/task/{tid}/schedstat") as fh:
                cpu_ns = int(fh.read().split()[0])
        except (OSError, ValueError, IndexError):  # the thread ended between listing and reading
            continue
        out[tid] = (stat[stat.rindex(")") + 2], cpu_ns)
    return out


def wait_until_idle() -> None:
    """Return once every other thread of this process (ORB-SLAM3's mapping, loop closing and
    global BA threads) has been idle over the last IDLE_WINDOW_S (the rule above), looked at
    every IDLE_SAMPLE_S; a thread that appears within the window counts from zero."""
    caller = threading.get_native_id()
    samples = [(time.monotonic_ns(), _threads(caller))]
    while True:
        time.sleep(IDLE_SAMPLE_S)
        end, now = time.monotonic_ns(), _threads(caller)
        samples.append((end, now))
        while end - samples[1][0] >= IDLE_WINDOW_S * 1e9:  # the latest start a whole window back
            samples.pop(0)
        start, before = samples[0]
        ran_ns = sum(cpu - before.get(tid, ("", 0))[1] for tid, (_, cpu) in now.items())
        if (
            end - start >= IDLE_WINDOW_S * 1e9
            and ran_ns < IDLE_CPU_SHARE * (end - start)
            and not any(state in "RD" for state, _ in now.values())
        ):
            return


def check_pacing() -> str | None:
    """Why this system cannot pace ORB-SLAM3 (wait_until_idle reads Linux's /proc), or None."""
    try:
        _threads(-1)
        with open(f"/proc/self/task/{threading.get_native_id()}/schedstat") as fh:
            int(fh.read().split()[0])
    except (OSError, ValueError, IndexError) as exc:
        return f"cannot pace ORB-SLAM3 by its threads' scheduler accounting (/proc/self/task/*/schedstat): {exc}"
    return None


def serve(conn, vocabulary: str, settings: str, log_path: str) -> None:
    """The child's main: load ORB-SLAM3 (monocular, no viewer) and answer the parent's messages
    until "finish" or the pipe closes. Ctrl-C is the parent's to handle (it ends the child)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    log = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o666)
    os.dup2(log, 1)
    os.dup2(log, 2)
    problem = check_pacing()
    if problem:
        conn.send(("error", problem))
        return
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
            wait_until_idle()
            pose = result.pose_wc if result.pose_valid else None
            conn.send(
                (
                    "tracked",
                    STATE_NAMES.get(result.state.name, result.state.name.lower()),
                    int(result.num_tracked_points),
                    pose,
                )
            )
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
