"""What a run does with its gyro, decided once (`assess`): whether the tracker keeps it or the
frames are tracked again without it, the frames where the scene moved while the gyro read still,
the clock the backend reads it on, and what the run's summary says about it."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle, matrix_to_rotvec, rotvec_to_matrix
from eas_vo.imu.fit import ImuAgreement, imu_agreement
from eas_vo.imu.thresholds import MIN_AGREEMENT_PAIRS
from eas_vo.imu.verdict import GyroVerdict, judge_gyro, without
from eas_vo.types import FrameRecord, ImuSeries, RelativeRotation

#: Above this angle [deg] the gyro and the tracker disagree on the axes: a wrong axis convention
#: is 90 or 180 deg, right mounts fit within a few degrees (docs/imu.md, "How the check's
#: thresholds were chosen").
IMU_DISAGREEMENT_DEG = 10.0
#: The gyro's clock is off when reading it this much later or earlier [s] explains the tracked
#: rotations clearly better (CLOCK_GAIN: the median residual at most this part of the configured
#: clock's); above the images' own lag (docs/imu.md, same section).
CLOCK_OFF_S = 0.002
CLOCK_GAIN = 0.9
#: Below this spread (ImuAgreement.spread) the camera turned about one axis only and the fit
#: cannot tell how the gyro is turned about it (a pure pan is under 0.05, hand-held motion
#: about 0.5; docs/imu.md).
MIN_SPREAD = 0.2
#: The axes are taken for off (beyond IMU_DISAGREEMENT_DEG) only beyond this many standard
#: deviations of the fit too (ImuAgreement.turned_sigma_deg): the images' errors are correlated
#: from pair to pair (lag, blur), which the fit's scatter understates (docs/imu.md).
AXES_SIGMAS = 5.0
#: A fit this close [deg] to an axis swap or flip is taken for it (those are 90 deg apart).
AXES_SNAP_DEG = 20.0


@dataclass(frozen=True)
class GyroSetup:
    """What the policy needs to know of the run: the gyro's configured place and clock (the
    [run] settings named in its messages) and the plugins that would read it."""

    rotvec_cam: tuple[float, float, float]  # run.imu_rotvec_cam [rad]
    time_offset_s: float  # run.imu_time_offset_s
    time_offset_auto: bool  # run.imu_time_offset_auto
    frontend: str  # the plugins' names, for messages
    tracker: str
    backend: str
    images_lag: bool = False  # the frontend shows the past (Frontend.shows_the_past)
    tracker_reads_images: bool = True  # Tracker.reads_images
    tracker_uses_imu: bool = False  # Tracker.uses_imu and its Tracker.imu_use
    tracker_imu_use: str = ""
    backend_uses_imu: bool = False  # Backend.uses_imu and its Backend.imu_use
    backend_imu_use: str = ""


@dataclass(frozen=True)
class GyroDecision:
    """What the run does with its gyro (`assess`).

    Attributes:
        use: the images' verdict (GyroVerdict.use; metrics.json `gyro`), None without a gyro.
        retrack: the frames are to be taken as tracked again without the gyro.
        still: frame index -> angle [rad] between the tracker's and the gyro's rotation, where
            the tracker turned while a gyro the images do not contradict read still.
        backend_imu: the gyro the backend gets (None: none), on the clock `imu_time_offset_s`.
        imu_time_offset_s: the time offset [s] the backend reads the gyro with (None without one).
        reclocked: that offset was found from the images (run.imu_time_offset_auto).
        warnings: what the checks found, for the run's warnings.
        readers: what read the gyro, for the summary (metrics.json `gyro_use`), None when nothing did.
    """

    use: str | None = None
    retrack: bool = False
    still: dict[int, float] = field(default_factory=dict)
    backend_imu: ImuSeries | None = None
    imu_time_offset_s: float | None = None
    reclocked: bool = False
    warnings: tuple[str, ...] = ()
    readers: str | None = None

    def weakened(
        self, records: list[FrameRecord], edges: list[RelativeRotation]
    ) -> tuple[list[FrameRecord], list[RelativeRotation]]:
        """`records` and `edges` with the `still` frames `weak` (the reason says how far apart)
        and their edges' sigma at least the angle apart per axis (over sqrt(3)), so that a
        backend weighing edges by their covariance trusts the gyro there."""
        records = [
            dataclasses.replace(
                r,
                status="weak",
                reason=f"turns while the gyro reads still ({np.degrees(self.still[r.index]):.2f} deg apart)",
            )
            if r.index in self.still
            else r
            for r in records
        ]
        edges = [
            dataclasses.replace(e, covariance=_at_least(e.noise_covariance(), self.still[e.j] / np.sqrt(3.0)))
            if e.j == e.i + 1 and not e.loop and e.j in self.still
            else e
            for e in edges
        ]
        return records, edges


def assess(
    imu: ImuSeries | None,
    times: np.ndarray,
    edges: list[RelativeRotation],
    setup: GyroSetup,
    retrack: Callable[[], tuple[np.ndarray, list[RelativeRotation]]] | None = None,
) -> GyroDecision:
    """Decide what the run does with `imu` (camera frame, frames' clock; None without one), from
    the tracked frame times [s] and edges.

    The images judge the gyro (verdict.judge_gyro). When the tracker predicted from a gyro the
    images contradict or cannot check (a wrong one misleads LK until nothing is measured
    confidently), `retrack()` tracks the frames again without it and returns their times and
    edges: that tracking is kept (`retrack`) if the first was contradicted or if it can judge
    the gyro, whose verdict it then gives. The axes and clock are then fitted (fit.imu_agreement)
    on the kept tracking, less the frames where the scene moved (`still`)."""
    if imu is None:
        return GyroDecision()
    verdict = judge_gyro(times, edges, imu)
    retracked = False
    if verdict.use != "used" and setup.tracker_uses_imu and retrack is not None:
        second_times, second_edges = retrack()
        second = judge_gyro(second_times, second_edges, imu)
        if verdict.contradicts or second.can_tell:
            times, edges, retracked = second_times, second_edges, True
            verdict = verdict if verdict.contradicts else second
    still = {} if verdict.contradicts else dict(verdict.still)
    agreement = imu_agreement(times, without(edges, set(still)), imu)
    backend_imu, offset = backend_gyro(setup, None if verdict.contradicts else imu, agreement)
    reclocked = offset is not None and offset != setup.time_offset_s
    findings = disagreements(setup, agreement, reclocked)
    return GyroDecision(
        verdict.use,
        retracked,
        still,
        backend_imu,
        offset,
        reclocked,
        tuple(verdict.warnings(retracked, findings)),
        gyro_readers(setup, verdict, retracked),
    )


def _axis_rotations() -> list[np.ndarray]:
    """The 24 rotations that permute and flip axes: how IMU axis conventions differ."""
    rotations = []
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            R = np.zeros((3, 3))
            R[range(3), order] = signs
            if np.linalg.det(R) > 0:
                rotations.append(R)
    return rotations


def _conclusive(agreement: ImuAgreement | None) -> bool:
    """Whether the check can say anything: at least half the frame pairs (and MIN_AGREEMENT_PAIRS) agree."""
    return agreement is not None and agreement.agreeing >= max(MIN_AGREEMENT_PAIRS, agreement.pairs / 2)


def _axes_off(agreement: ImuAgreement | None) -> bool:
    """Whether the gyro agrees with the images only turned by more than IMU_DISAGREEMENT_DEG
    and AXES_SIGMAS times the fit's own uncertainty (about more than one axis: MIN_SPREAD)."""
    return (
        _conclusive(agreement)
        and agreement.spread >= MIN_SPREAD
        and (
            agreement.mirrored
            or agreement.turned_deg > max(IMU_DISAGREEMENT_DEG, AXES_SIGMAS * agreement.turned_sigma_deg)
        )
    )


def _clock_is_off(agreement: ImuAgreement | None) -> bool:
    """Whether the images clearly ask for the gyro read CLOCK_OFF_S or more off its clock.
    Not judged while the axes are off: a tracker predicting from a wrongly turned gyro leans
    its tracks towards it, which reads as a clock offset."""
    return (
        _conclusive(agreement)
        and not _axes_off(agreement)
        and abs(agreement.clock_shift_s) >= CLOCK_OFF_S
        and agreement.residual_rad <= CLOCK_GAIN * agreement.residual_unshifted_rad
    )


def _reclocks(setup: GyroSetup, agreement: ImuAgreement | None) -> bool:
    """Whether run.imu_time_offset_auto re-times the gyro for the backend: it reads the gyro,
    the images clearly ask for another clock, found within the search, and the images do not
    show the past (their lag would then pass for the gyro's clock; docs/imu.md)."""
    return (
        setup.time_offset_auto
        and setup.backend_uses_imu
        and _clock_is_off(agreement)
        and not agreement.shift_at_limit
        and not setup.images_lag
    )


def backend_gyro(
    setup: GyroSetup, imu: ImuSeries | None, agreement: ImuAgreement | None
) -> tuple[ImuSeries | None, float | None]:
    """The gyro the backend gets and the time offset [s] it is read with: as configured, or
    (_reclocks) on the clock the images ask for. With an online backend that clock was found
    over the whole sequence, so its causal estimates are no longer strictly causal."""
    if imu is None:
        return None, None
    if not _reclocks(setup, agreement):
        return imu, setup.time_offset_s
    shift = agreement.clock_shift_s
    return ImuSeries(imu.t - shift, imu.acc, imu.gyro), setup.time_offset_s + shift


def disagreements(setup: GyroSetup, agreement: ImuAgreement | None, reclocked: bool) -> list[str]:
    """Warnings when the gyro's rotations agree with the tracker's only once turned by more
    than IMU_DISAGREEMENT_DEG (and the motion turned about more than one axis), or (unless
    `reclocked`: backend_gyro took care of it) clearly better read CLOCK_OFF_S or more off its
    configured clock (judged once the axes agree), naming the run.imu_rotvec_cam (an axis swap
    or flip within AXES_SNAP_DEG of the fit) or run.imu_time_offset_s the data suggest. Silent
    when fewer than half the frame pairs agree with any rotation, which says nothing either way."""
    warnings = []
    if _axes_off(agreement):
        warnings.append(_axes_warning(setup, agreement))
    if _clock_is_off(agreement) and not reclocked:
        warnings.append(_clock_warning(setup, agreement))
    return warnings


def _clock_warning(setup: GyroSetup, agreement: ImuAgreement) -> str:
    """What the clock check says. The shift is between the gyro and the time the images show:
    the IMU's clock, or, for a frontend that shows the past (a time surface), the images' lag."""
    shift, configured = agreement.clock_shift_s, setup.time_offset_s
    at_least = "at least " if agreement.shift_at_limit else ""
    found = (
        f"the gyro agrees best with the tracked rotations read {at_least}{abs(shift) * 1e3:.1f} ms "
        f"{'later' if shift > 0 else 'earlier'} than configured (median residual {np.degrees(agreement.residual_rad):.2f} "
        f"against {np.degrees(agreement.residual_unshifted_rad):.2f} deg)"
    )
    if setup.images_lag:
        return (
            f"{found}: the {setup.frontend} images show the past, so this is taken for their lag and the "
            f"IMU's clock is kept; to check the clock itself, run a frontend of the present (e.g. eas)"
        )
    return (
        f"{found}: the IMU's clock, or the time {_measured_from(setup)} show, is off by that; "
        f"run.imu_time_offset_s = {at_least}{configured + shift:.4f} would match them, not {configured:.10g}"
    )


def _axes_warning(setup: GyroSetup, agreement: ImuAgreement) -> str:
    """What the axes check says: how far the gyro is turned and the place that explains it."""
    R_configured = rotvec_to_matrix(setup.rotvec_cam)
    R_imu_cam = R_configured @ agreement.R
    axes = min(_axis_rotations(), key=lambda R: geodesic_angle(R, R_imu_cam))
    off = np.degrees(geodesic_angle(axes, R_imu_cam))
    moved = agreement.mirrored or np.degrees(geodesic_angle(axes, R_configured)) > IMU_DISAGREEMENT_DEG
    if off < AXES_SNAP_DEG and moved:
        kind = "the identity" if np.allclose(axes, np.eye(3)) else "axes swapped or flipped"
        looks, how = axes, f"{kind}, {off:.1f} deg from the fit"
    else:
        looks, how = R_imu_cam, "fitted"

    def vector(v) -> str:
        return "[" + ", ".join(f"{float(x) + 0.0:.10g}" if abs(x) > 1e-12 else "0" for x in v) + "]"

    if agreement.mirrored:
        return (
            f"the gyro agrees with the tracked rotations only with its rates negated ({agreement.agreeing} of "
            f"{agreement.pairs} frame pairs): its axes are mirrored (a left-handed convention), which no "
            f"run.imu_rotvec_cam undoes; negate its rates in the file, then run.imu_rotvec_cam = "
            f"{vector(matrix_to_rotvec(looks))} ({how})"
        )
    return (
        f"the gyro agrees with the tracked rotations only turned by {agreement.turned_deg:.1f} deg ({agreement.agreeing} of "
        f"{agreement.pairs} frame pairs): the IMU looks mounted as run.imu_rotvec_cam = {vector(matrix_to_rotvec(looks))} "
        f"({how}), not {vector(setup.rotvec_cam)}; check it and the camera calibration"
    )


def gyro_readers(setup: GyroSetup, verdict: GyroVerdict | None, retracked: bool) -> str | None:
    """What read the gyro, for the run's summary: the tracker (its Tracker.imu_use) unless the
    frames were tracked again without it, the backend (its Backend.imu_use) unless the images
    contradict it; None when nothing did."""
    if verdict is None or verdict.contradicts:
        return None
    uses = []
    if setup.tracker_uses_imu and not retracked:
        uses.append(
            f"by the {setup.tracker} tracker as {setup.tracker_imu_use} "
            f"(the rotations measured from {_measured_from(setup)})"
        )
    if setup.backend_uses_imu:
        uses.append(f"by the {setup.backend} backend as {setup.backend_imu_use}")
    return " and ".join(uses) or None


def _measured_from(setup: GyroSetup) -> str:
    """What the tracker measures its rotations from, for a message: the frontend's images, or
    the events for a tracker that reads no images."""
    return f"the {setup.frontend} images" if setup.tracker_reads_images else "the events"


def _at_least(covariance: np.ndarray, sigma_rad: float) -> np.ndarray:
    """`covariance` [rad^2] (3, 3) with its variance along every axis at least sigma_rad^2."""
    w, V = np.linalg.eigh(covariance)
    return (V * np.maximum(w, sigma_rad**2)) @ V.T
