"""Rotation-only pose graph with GTSAM: one Rot3 per frame, a prior on the first,
a BetweenFactorRot3 per measured relative rotation (consecutive or skip edges); each frame's
marginal covariance (gtsam.Marginals, or iSAM2's) as BackendResult.covariance.

Keys (gtsam.symbol_shorthand): A(k) frame k's attitude R_w_ck, B(0) the gyro's bias [rad/s].
Every A key sorts below B(0), as the plain frame numbers did: GTSAM's elimination order depends
on the keys' order, and another order changes the results' last bits."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from eas_vo.errors import ConfigError
from eas_vo.geometry.rotations import geodesic_angle
from eas_vo.geometry.uncertainty import chain_covariance
from eas_vo.imu.verdict import confident_steps, disagreement
from eas_vo.plugins import Backend, BackendResult
from eas_vo.types import ImuSeries, RelativeRotation
from eas_vo.validation import check_choice, check_range

MODES = ("batch", "online")
ROBUST = ("none", "huber", "cauchy")
EDGE_NOISE = ("covariance", "inliers")
#: A gyro interval a confident edge contradicts is left out only when the two differ by more
#: than this many times their median difference over the sequence (chosen above what the images'
#: errors showed beside a right gyro: docs/imu.md, "A gyro that cannot be right is not used").
GATE_SPREAD = 10.0
#: Levenberg-Marquardt stopped by backend.iterations has converged for every purpose when one
#: more step turns no frame by more than this [rad] (a thousandth of the smallest APE reported).
CONVERGED_STEP_RAD = 1e-6
#: The prior holding frame 0 at the identity (as Backend.solve promises) [rad]: every other
#: factor is relative, so it fixes the graph's one free global rotation; this far below any
#: edge's noise, frame 0 stays put.
FIRST_FRAME_SIGMA_RAD = 1e-9
#: The loosest edge noise [rad]: an edge's own (RelativeRotation.noise_covariance, infinite
#: without inliers) is capped here along every axis, since GTSAM's noise models need a finite
#: sigma; an edge this loose carries no information.
LOOSEST_EDGE_SIGMA_RAD = 1e3
#: Levenberg-Marquardt stops when an iteration lowers the graph's error by less than this fraction
#: of it (relative) or this amount (absolute; the error is half the sum of squared whitened
#: residuals). Far below GTSAM's defaults (1e-5 each), so the solve runs to the error's numerical
#: floor or to backend.iterations, where CONVERGED_STEP_RAD judges whether it had converged.
LM_RELATIVE_ERROR_TOL = 1e-12
LM_ABSOLUTE_ERROR_TOL = 1e-15
#: iSAM2 relinearises a variable whose estimate moved by more than this since it was last
#: linearised [rad for a frame, rad/s for the bias], checking at every update (skip 1). With
#: GTSAM's defaults (0.1, every 10th update) stale linearisation points keep the online estimates,
#: causal and final, short of the optimum the batch solve finds; tests/backends/test_gtsam_graph.py
#: holds them to it.
ISAM2_RELINEARIZE_THRESHOLD = 1e-6
ISAM2_RELINEARIZE_SKIP = 1


@dataclass(frozen=True)
class GtsamConfig:
    """Attributes:
    mode: `batch` (Levenberg-Marquardt over all frames) or `online` (iSAM2, frame by frame:
        BackendResult.causal_R_w_c holds each frame's estimate as it was when that frame
        arrived).
    edge_noise: an edge's noise model: `covariance` (the default): its estimator's own
        covariance (RelativeRotation.noise_covariance: full 3x3; from its quality where the
        tracker gives none), no axis's sigma below sigma_floor_rad; `inliers`: one isotropic
        sigma for every edge, sigma_rad * sqrt(reference_inliers / inliers), whatever its
        covariance (the graph before covariances, for comparison).
    sigma_rad: (`inliers`) noise of an edge measured with `reference_inliers` inliers.
    reference_inliers: see sigma_rad.
    sigma_floor_rad: (`covariance`) the smallest noise along any axis [rad].
    gap_sigma_rad: a frame without a measurement is tied to the previous one by an
        identity edge this loose (the chain's "keep the previous rotation").
    robust, robust_k: robust kernel (`none`, `huber`, `cauchy`) and its threshold in sigmas of
        each edge's noise model. `cauchy` (2 sigmas): of the kernels, the one that on the choice
        data (synthetic:default and the real excerpt's first 20 s, paper.toml with keyframe
        edges, every frontend) made the graph worse than the chain on the fewest runs and
        better by the largest geometric mean (benchmarks/graph_vs_chain.py;
        docs/uncertainty.md reports it on other data).
    iterations: Levenberg-Marquardt iterations (batch) or extra iSAM2 updates at the end.
    gyro: fuse the dataset's gyro: `true` (a dataset without an IMU is refused), `false`,
        or `auto` (when the dataset has an IMU): readings preintegrated between frames
        (PreintegratedAhrsMeasurements) in AHRSFactors sharing one bias variable; the
        readings come in the camera frame (the run's `imu_rotvec_cam`).
    gyro_noise: gyro white-noise density [rad/s/sqrt(Hz)].
    gyro_bias_sigma: prior on the gyro bias [rad/s]: its standard deviation about zero.
        Both default to the DAVIS IMU the simulator models (ImuModel: gyro_noise,
        gyro_bias); for another IMU, take them from its calibration (e.g. Kalibr's
        gyroscope_noise_density). A looser prior lets the images' own systematic errors
        (lag, blur) pass for a gyro bias that the graph then integrates (docs/imu.md,
        "How readings are integrated").
    """

    mode: str = "batch"
    edge_noise: str = "covariance"
    sigma_rad: float = 0.005
    reference_inliers: int = 100
    sigma_floor_rad: float = 1e-4
    gap_sigma_rad: float = 1.0
    robust: str = "cauchy"
    robust_k: float = 2.0
    iterations: int = 50
    gyro: bool | str = False
    gyro_noise: float = 0.003
    gyro_bias_sigma: float = 0.01

    def validate(self) -> None:
        if not (isinstance(self.gyro, bool) or self.gyro == "auto"):
            raise ConfigError(f"gyro = {self.gyro!r}; allowed: true, false, auto")
        check_range(self, "gyro_noise", 0.0, 10.0, lo_open=True)
        check_range(self, "gyro_bias_sigma", 0.0, 10.0, lo_open=True)
        check_choice(self, "mode", MODES)
        check_choice(self, "robust", ROBUST)
        check_range(self, "sigma_rad", 0.0, 10.0, lo_open=True)
        check_range(self, "reference_inliers", 1, 10**6)
        check_choice(self, "edge_noise", EDGE_NOISE)
        check_range(self, "sigma_floor_rad", 0.0, 10.0, lo_open=True)
        check_range(self, "gap_sigma_rad", 0.0, 1e3, lo_open=True)
        check_range(self, "robust_k", 0.0, 1e3, lo_open=True)
        check_range(self, "iterations", 1, 10_000)


class GtsamBackend(Backend):
    """Smooths the chained rotations with a rotation-only pose graph (GTSAM)."""

    name = "gtsam"
    description = "rotation-only pose graph (GTSAM Rot3): batch Levenberg-Marquardt or online iSAM2"
    Config = GtsamConfig

    @property
    def needs_imu(self) -> bool:
        return self.config.gyro is True

    @property
    def uses_imu(self) -> bool:
        return self.config.gyro in (True, "auto")

    def edge_covariance(self, edge: RelativeRotation) -> np.ndarray:
        """The noise covariance [rad^2] (3, 3) of a measured edge in its factor (see edge_noise;
        RelativeRotation's convention, which is GTSAM's)."""
        c = self.config
        if c.edge_noise == "inliers":
            return (c.sigma_rad**2 * c.reference_inliers / max(edge.inliers, 1)) * np.eye(3)
        covariance = np.nan_to_num(edge.noise_covariance(), nan=np.inf)
        if not np.all(np.isfinite(covariance)):
            return LOOSEST_EDGE_SIGMA_RAD**2 * np.eye(3)
        w, V = np.linalg.eigh(0.5 * (covariance + covariance.T))
        return (V * np.clip(w, c.sigma_floor_rad**2, LOOSEST_EDGE_SIGMA_RAD**2)) @ V.T

    def _noise(self, gtsam, covariance: np.ndarray):
        """The factor's noise model: Gaussian with `covariance`, under the robust kernel, which then
        acts on the residual whitened by it (in its sigmas)."""
        c = self.config
        base = gtsam.noiseModel.Gaussian.Covariance(covariance)
        if c.robust == "none":
            return base
        estimator = gtsam.noiseModel.mEstimator.Huber if c.robust == "huber" else gtsam.noiseModel.mEstimator.Cauchy
        return gtsam.noiseModel.Robust.Create(estimator.Create(c.robust_k), base)

    def _factors(self, gtsam, n_frames: int, edges: Sequence[RelativeRotation]) -> dict[int, list]:
        """Factors grouped by the newest frame they involve (what an online solver gets when)."""
        from gtsam.symbol_shorthand import A

        c = self.config
        by_frame: dict[int, list] = {k: [] for k in range(n_frames)}
        at_identity = gtsam.noiseModel.Isotropic.Sigma(3, FIRST_FRAME_SIGMA_RAD)
        by_frame[0].append(gtsam.PriorFactorRot3(A(0), gtsam.Rot3(), at_identity))
        measured = set()
        for e in edges:
            by_frame[e.j].append(
                gtsam.BetweenFactorRot3(
                    A(e.i), A(e.j), gtsam.Rot3(e.R_i_j), self._noise(gtsam, self.edge_covariance(e))
                )
            )
            measured.add(e.j)
        gap = gtsam.noiseModel.Isotropic.Sigma(3, c.gap_sigma_rad)
        for k in range(1, n_frames):
            if k not in measured:
                by_frame[k].append(gtsam.BetweenFactorRot3(A(k - 1), A(k), gtsam.Rot3(), gap))
        return by_frame

    def _gyro_factors(
        self, gtsam, by_frame: dict, times: np.ndarray, imu, edges: Sequence[RelativeRotation]
    ) -> list[str]:
        """AHRSFactors between consecutive frames (rates linear between readings: ImuSeries.rates_between)
        over the intervals the gyro measures (ImuSeries.covered) that last some time, except where a
        confident measurement of the images contradicts the gyro (_contradicted): a gate, so that a
        glitch of the gyro never overrides the images. Returns the warning that says so, if any.

        The bias is sought about zero: its prior's mean and the preintegration's bias estimate."""
        from gtsam.symbol_shorthand import A, B

        c = self.config
        params = gtsam.PreintegratedRotationParams()
        params.setGyroscopeCovariance(c.gyro_noise**2 * np.eye(3))
        by_frame[0].append(
            gtsam.PriorFactorVector(B(0), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, c.gyro_bias_sigma))
        )
        measured = imu.covered(times[:-1], times[1:]) & (np.diff(times) > 0)  # no factor over no time
        contradicted = self._contradicted(times, edges, imu)
        for k in np.flatnonzero(measured & ~contradicted) + 1:
            pim = gtsam.PreintegratedAhrsMeasurements(params, np.zeros(3))
            for rate, dt in zip(*imu.rates_between(times[k - 1], times[k])):
                pim.integrateMeasurement(rate, dt)
            by_frame[k].append(gtsam.AHRSFactor(A(k - 1), A(k), B(0), pim))
        if not contradicted.any():
            return []
        first = int(np.flatnonzero(contradicted)[0]) + 1
        return [
            f"the gyro was left out of {int(contradicted.sum())} frame interval(s), where a confident measurement of "
            f"the images contradicts it (the first ending at frame {first}, t={times[first]:.6f} s)"
        ]

    @staticmethod
    def _contradicted(times: np.ndarray, edges: Sequence[RelativeRotation], imu: ImuSeries) -> np.ndarray:
        """Which consecutive frame intervals (len(times) - 1,) a confident edge
        (imu.verdict.confident_steps) contradicts: the two rotations differ by more than
        imu.verdict.DISAGREEMENT of the larger and by more than GATE_SPREAD times their median
        difference over the sequence (the images' own errors are heavy-tailed: a gate on their
        modelled sigma would leave out a right gyro where the images erred)."""
        steps, R_vision, R_gyro = confident_steps(times, edges, imu)
        judged, disagree, off = disagreement(R_gyro, R_vision)
        typical = np.median(off[judged]) if judged.any() else np.inf
        out = np.zeros(len(times) - 1, bool)
        out[[e.i for e, gated in zip(steps, disagree & (off > GATE_SPREAD * typical)) if gated]] = True
        return out

    def solve(
        self,
        n_frames: int,
        edges: Sequence[RelativeRotation],
        *,
        times: np.ndarray | None = None,
        imu: ImuSeries | None = None,
    ) -> BackendResult:
        import gtsam

        from eas_vo.backends.chain import chain_rotations

        initial_R = chain_rotations(n_frames, edges)
        by_frame = self._factors(gtsam, n_frames, edges)
        with_bias = self.uses_imu and imu is not None
        if with_bias and times is None:
            raise ValueError("gyro fusion needs the frame times")
        warnings = self._gyro_factors(gtsam, by_frame, np.asarray(times, float), imu, edges) if with_bias else []
        solve = self._batch if self.config.mode == "batch" else self._online
        try:
            solved = solve(gtsam, n_frames, by_frame, initial_R, with_bias)
        except RuntimeError as exc:  # gtsam's own errors (an indeterminate system, ...) are RuntimeErrors
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            failed = (
                f"the pose graph could not be solved ({self.config.mode}: {reason}): "
                "the rotations are the chained measurements, unsmoothed"
            )
            return BackendResult(initial_R, warnings=(*warnings, failed), covariance=chain_covariance(n_frames, edges))
        return replace(solved, warnings=(*warnings, *solved.warnings))

    def _batch(self, gtsam, n_frames: int, by_frame: dict, initial_R: np.ndarray, with_bias: bool) -> BackendResult:
        """Levenberg-Marquardt over every frame from the chained rotations (and a zero bias)."""
        from gtsam.symbol_shorthand import A, B

        graph = gtsam.NonlinearFactorGraph()
        initial = gtsam.Values()
        for k in range(n_frames):
            for factor in by_frame[k]:
                graph.add(factor)
            initial.insert(A(k), gtsam.Rot3(initial_R[k]))
        if with_bias:
            initial.insert(B(0), np.zeros(3))
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.config.iterations)
        params.setRelativeErrorTol(LM_RELATIVE_ERROR_TOL)
        params.setAbsoluteErrorTol(LM_ABSOLUTE_ERROR_TOL)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        start_error = graph.error(initial)
        result = optimizer.optimize()
        if not np.isfinite(optimizer.error()) or optimizer.error() > start_error:
            raise RuntimeError(
                f"Levenberg-Marquardt ended at error {optimizer.error():.6g}, above its start {start_error:.6g}"
            )
        R_w_c = np.stack([result.atRot3(A(k)).matrix() for k in range(n_frames)])
        covariance, warnings = _marginal_covariances(
            lambda: gtsam.Marginals(graph, result).marginalCovariance, n_frames
        )
        if optimizer.iterations() >= self.config.iterations:
            moved = self._next_step_rad(optimizer, R_w_c)
            if moved > CONVERGED_STEP_RAD:
                warnings += (
                    f"the pose graph's Levenberg-Marquardt stopped at backend.iterations = {self.config.iterations} before "
                    f"converging (error {start_error:.6g} -> {optimizer.error():.6g}; one more step turns a frame by "
                    f"{np.degrees(moved):.2g} deg): raise it",
                )
        return BackendResult(R_w_c, warnings=warnings, covariance=covariance)

    @staticmethod
    def _next_step_rad(optimizer, R_w_c: np.ndarray) -> float:
        """How far [rad] the optimizer's next Levenberg-Marquardt iteration (from where it stopped,
        its damping as it was) turns the frame it turns most from R_w_c (0 where no step lowers
        the error: a minimum; infinite where the step fails)."""
        from gtsam.symbol_shorthand import A

        try:
            optimizer.iterate()
            step = optimizer.values()
            return float(geodesic_angle(R_w_c, np.stack([step.atRot3(A(k)).matrix() for k in range(len(R_w_c))])).max())
        except RuntimeError:
            return float("inf")

    def _online(self, gtsam, n_frames: int, by_frame: dict, initial_R: np.ndarray, with_bias: bool) -> BackendResult:
        """iSAM2, one update per frame (its estimate then is the causal one), then
        backend.iterations more updates for the final rotations."""
        from gtsam.symbol_shorthand import A, B

        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(ISAM2_RELINEARIZE_THRESHOLD)
        params.relinearizeSkip = ISAM2_RELINEARIZE_SKIP
        isam = gtsam.ISAM2(params)
        causal = np.empty((n_frames, 3, 3))
        previous = np.eye(3)
        for k in range(n_frames):
            graph = gtsam.NonlinearFactorGraph()
            for factor in by_frame[k]:
                graph.add(factor)
            values = gtsam.Values()
            # the new frame starts where the chain puts it relative to the current estimate of k-1
            step = initial_R[k - 1].T @ initial_R[k] if k else np.eye(3)
            values.insert(A(k), gtsam.Rot3(previous @ step))
            if k == 0 and with_bias:
                values.insert(B(0), np.zeros(3))
            isam.update(graph, values)
            estimate = isam.calculateEstimate()
            causal[k] = estimate.atRot3(A(k)).matrix()
            previous = causal[k]
        for _ in range(self.config.iterations):
            isam.update()
        estimate = isam.calculateEstimate()
        covariance, warnings = _marginal_covariances(lambda: isam.marginalCovariance, n_frames)
        return BackendResult(
            np.stack([estimate.atRot3(A(k)).matrix() for k in range(n_frames)]),
            causal_R_w_c=causal,
            warnings=warnings,
            covariance=covariance,
        )


def _marginal_covariances(marginal_of, n_frames: int) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """Each frame's marginal covariance [rad^2] (n_frames, 3, 3) from `marginal_of()` (key ->
    covariance: gtsam.Marginals(...).marginalCovariance or ISAM2.marginalCovariance), and no
    warning; None and a warning when GTSAM cannot compute them. GTSAM's Rot3 covariance is that of
    the local (right) perturbation R Exp(delta), the camera frame: BackendResult.covariance's
    convention (tests/backends/test_gtsam_graph.py holds it)."""
    from gtsam.symbol_shorthand import A

    try:
        marginal = marginal_of()
        return np.stack([np.asarray(marginal(A(k)), float) for k in range(n_frames)]), ()
    except RuntimeError as exc:  # gtsam's own errors (an indeterminate system, ...) are RuntimeErrors
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return None, (f"the pose graph's marginal covariances could not be computed ({reason}): no covariance",)
