"""Whether a dataset's gyro readings can be right, before any work: rates no gyro measures, a
stuck sensor, fewer readings than frames, clock units and coverage of the frame intervals."""

from __future__ import annotations

import numpy as np

from eas_vo.errors import EasVoError
from eas_vo.types import MAX_GAP_READINGS, TIME_UNITS, ImuSeries

#: No MEMS gyro measures faster [rad/s]: the widest full scale sold is +-4000 deg/s (e.g.
#: TDK InvenSense ICM-20649; the DAVIS240's MPU-6150 and the DAVIS346's MPU-6500 reach 2000).
MAX_GYRO_RAD_S = float(np.radians(4000.0))


def check_readings(imu: ImuSeries, frame_times: np.ndarray, label: str, offset_s: float) -> list[str]:
    """Refuse (EasVoError) a gyro whose readings cannot be right for the frames at
    `frame_times` [s] (the run's window); return warnings for what is only incomplete.

    `offset_s`: the run's imu_time_offset_s, named in the messages about coverage."""
    where = f"{label}: the IMU"
    n = len(imu.t)
    if n < 2:
        raise EasVoError(f"{where} holds {n} reading(s): a gyro needs at least 2 to measure a rotation")
    rates = np.abs(imu.gyro)
    if not np.all(np.isfinite(rates)):
        k = int(np.flatnonzero(~np.isfinite(rates).all(axis=1))[0])
        raise EasVoError(f"{where}'s reading {k} (t={imu.t[k]:.6f} s) is not finite")
    k = int(np.argmax(rates.max(axis=1)))
    if rates[k].max() > MAX_GYRO_RAD_S:
        raise EasVoError(
            f"{where}'s reading {k} (t={imu.t[k]:.6f} s) turns at {rates[k].max():.4g} rad/s, faster than any MEMS "
            f"gyro measures ({MAX_GYRO_RAD_S:.1f} rad/s = 4000 deg/s): the rates must be in rad/s (not deg/s), "
            "and a glitch must be removed from the file"
        )
    if np.all(np.ptp(imu.gyro, axis=0) == 0):
        raise EasVoError(
            f"{where} reads {_vector(imu.gyro[0])} rad/s in every one of its {n} readings: a gyro's own "
            "noise moves its readings, so this one is stuck or not connected"
        )
    steps = np.diff(frame_times)
    frames_dt = float(np.median(steps[steps > 0])) if np.any(steps > 0) else np.inf  # repeated times are no interval
    imu_dt = float(np.median(np.diff(imu.t)))
    if imu_dt > frames_dt:
        raise EasVoError(
            f"{where} reads every {imu_dt:.4g} s ({1 / imu_dt:.4g} Hz), less often than the frames "
            f"({1 / frames_dt:.4g} Hz): it cannot measure the rotation between two frames{_unit_hint(imu, frame_times)}"
        )
    t0, t1 = frame_times[:-1], frame_times[1:]
    covered = imu.covered(t0, t1)
    span = (
        f"readings {imu.t[0]:.3f}-{imu.t[-1]:.3f} s on the frames' clock with run.imu_time_offset_s = "
        f"{offset_s:.10g}; frames {frame_times[0]:.3f}-{frame_times[-1]:.3f} s"
    )
    if not covered.any():
        raise EasVoError(
            f"{where} measures none of the window's {len(t0)} frame intervals ({span}): check the IMU "
            f"file's clock and run.imu_time_offset_s{_unit_hint(imu, frame_times)}"
        )
    if covered.all():
        return []
    return [
        f"the gyro measures {int(covered.sum())} of the window's {len(t0)} frame intervals ({span}; a gap over "
        f"{MAX_GAP_READINGS} reading intervals counts as none): the others are measured by the images alone"
    ]


def _unit_hint(imu: ImuSeries, frame_times: np.ndarray) -> str:
    """'; are its timestamps in microseconds?' when the IMU's time span is about 1e3, 1e6 or
    1e9 times the frames' (the readings' rate then looks that much lower)."""
    ratio = np.ptp(imu.t) / max(np.ptp(frame_times), 1e-12)
    for unit, factor in TIME_UNITS.items():
        if abs(np.log10(ratio / factor)) < 0.5:
            return f"; are its timestamps in {unit}? they must be in seconds"
    return ""


def _vector(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"
