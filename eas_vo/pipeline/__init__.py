"""One run of a frontend, tracker and backend on a dataset: `run` (runner) opens it (parts),
tracks it frame by frame (tracking), lets the gyro's policy decide once (eas_vo.imu.policy),
solves, evaluates (summary) and writes its files (outputs) with what made it (identity)."""

from eas_vo.pipeline.outputs import RUN_FILES, RunResult
from eas_vo.pipeline.parts import open_pipeline
from eas_vo.pipeline.runner import run

__all__ = ["RUN_FILES", "RunResult", "open_pipeline", "run"]
