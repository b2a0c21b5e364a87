"""ORB-SLAM3 in a child process (slam.worker): whether the `slam` extra is installed, the vocabulary
it reads, its frames fed one at a time and the state it reports for each."""

from __future__ import annotations

import importlib.util
import multiprocessing
import os
import signal
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError, EasVoError

EXTRA_HINT = "monocular ORB-SLAM3 runs through the optional extra: pip install 'eas-vo[slam]' (pyorbslam3, GPL-3.0)"


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


def relabel(states: list[str]) -> list[str]:
    """ORB-SLAM3's states with `relocalised` for an `ok` frame right after a lost one in the
    same map (it found its map again; an `ok` after `not_initialised` is a new initialisation)."""
    out, previous = [], "not_initialised"
    for s in states:
        out.append("relocalised" if s == "ok" and previous in ("recently_lost", "lost") else s)
        previous = s
    return out
