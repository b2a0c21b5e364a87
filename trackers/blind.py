"""`blind`: sees no image and no event, so measures no rotation, so that the backend's other inputs stand alone: with the gtsam
backend and its gyro, the gyro's dead reckoning through the same graph the trackers feed."""

from __future__ import annotations

import numpy as np

from eas_vo.plugins import Tracker
from eas_vo.types import FrameRecord, RelativeRotation


class BlindTracker(Tracker):
    """Reads neither images nor events; every frame after the first is `lost` ("no tracker")."""

    name = "blind"
    description = "sees nothing, measures nothing: the backend's other inputs alone (gtsam with gyro=true: the gyro's dead reckoning)"
    reads_images = False

    def reset(self) -> None:
        self._frames = 0

    def process(self, image: np.ndarray | None, t: float, **kwargs) -> tuple[FrameRecord, list[RelativeRotation]]:
        index, self._frames = self._frames, self._frames + 1
        status, reason = ("first", "") if index == 0 else ("lost", "the blind tracker measures nothing")
        return FrameRecord(index, t, 0, 0, status, False, reason=reason), []
