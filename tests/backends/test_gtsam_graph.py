"""The GTSAM pose-graph backend against the chain, on trajectories with exact ground truth."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.backends.chain import ChainBackend
from eas_vo.backends.gtsam_graph import GtsamBackend, GtsamConfig
from eas_vo.errors import ConfigError
from eas_vo.geometry.rotations import geodesic_angle, gyro_rotation
from eas_vo.geometry.uncertainty import chain_covariance
from eas_vo.types import RelativeRotation
from helpers import assert_rotations_close


def truth(n=120, seed=0):
    rng = np.random.default_rng(seed)
    steps = Rotation.from_rotvec(rng.normal(0, 0.02, (n, 3))).as_matrix()
    R = np.empty((n, 3, 3))
    R[0] = np.eye(3)
    for k in range(1, n):
        R[k] = R[k - 1] @ steps[k]
    return R


def measure(R, i, j, rng, noise_rad, inliers=100):
    """R_i_j with Gaussian noise of `noise_rad` per axis, and that noise as its covariance."""
    noise = Rotation.from_rotvec(rng.normal(0, noise_rad, 3)).as_matrix()
    return RelativeRotation(i, j, R[i].T @ R[j] @ noise, inliers, covariance=noise_rad**2 * np.eye(3))


def edges_for(R, seed=1, noise_rad=0.003, skip=0):
    rng = np.random.default_rng(seed)
    edges = [measure(R, k - 1, k, rng, noise_rad) for k in range(1, len(R))]
    if skip:
        edges += [measure(R, k - skip, k, rng, noise_rad) for k in range(skip, len(R), 1)]
    return edges


def ape(R_est, R_true):
    return float(np.mean(geodesic_angle(R_true, R_est)))


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_consecutive_edges_only_equals_the_chain(mode):
    R = truth()
    edges = edges_for(R)
    del edges[10]  # a frame without a measurement: both keep the previous rotation
    chain = ChainBackend().solve(len(R), edges).R_w_c
    graph = GtsamBackend(GtsamConfig(mode=mode)).solve(len(R), edges).R_w_c
    assert_rotations_close(graph, chain, 1e-9)


def test_multi_frame_edges_beat_the_chain():
    R = truth(seed=2)
    edges = edges_for(R, seed=3, skip=5)
    chain = ape(ChainBackend().solve(len(R), edges).R_w_c, R)
    graph = ape(GtsamBackend().solve(len(R), edges).R_w_c, R)
    assert graph < 0.7 * chain, (graph, chain)


def test_batch_and_online_agree_and_online_is_causal():
    R = truth(n=60, seed=4)
    edges = edges_for(R, seed=5, noise_rad=0.01, skip=3)
    # least squares, where iSAM2 and Levenberg-Marquardt reach one optimum to 1e-6 rad
    batch = GtsamBackend(GtsamConfig(mode="batch", robust="none")).solve(len(R), edges)
    online = GtsamBackend(GtsamConfig(mode="online", robust="none")).solve(len(R), edges)
    assert batch.causal_R_w_c is None
    assert_rotations_close(online.R_w_c, batch.R_w_c, 1e-6)
    for k in (10, 30):  # frame k's estimate as it was then: ~ the batch solution of frames 0..k
        past = [e for e in edges if e.j <= k]  # (iSAM2 takes one relinearisation step per frame)
        assert_rotations_close(
            online.causal_R_w_c[k], GtsamBackend(GtsamConfig(robust="none")).solve(k + 1, past).R_w_c[k], 5e-5
        )
        assert not np.allclose(online.causal_R_w_c[k], online.R_w_c[k], atol=1e-6)  # later frames did move it


def test_robust_kernel_resists_outlier_edges():
    R = truth(seed=6)
    edges = edges_for(R, seed=7, skip=4)
    rng = np.random.default_rng(8)
    outliers = [
        RelativeRotation(
            k - 4, k, Rotation.from_rotvec(rng.normal(0, 0.5, 3)).as_matrix(), 100, covariance=edges[0].covariance
        )
        for k in range(20, 110, 15)
    ]
    clean = ape(GtsamBackend(GtsamConfig(robust="huber")).solve(len(R), edges).R_w_c, R)
    plain = ape(GtsamBackend(GtsamConfig(robust="none")).solve(len(R), edges + outliers).R_w_c, R)
    for kernel in ("huber", "cauchy"):
        robust = ape(GtsamBackend(GtsamConfig(robust=kernel)).solve(len(R), edges + outliers).R_w_c, R)
        assert robust < 1.5 * clean + 1e-4, (kernel, robust, clean)
    assert plain > 3 * clean, (plain, clean)


def test_edge_noise_follows_inliers():
    """Two contradicting edges, least squares: the one with more inliers wins."""
    a = Rotation.from_rotvec([0, 0, 0.1]).as_matrix()
    b = Rotation.from_rotvec([0, 0, 0.2]).as_matrix()
    out = (
        GtsamBackend(GtsamConfig(edge_noise="inliers", robust="none"))
        .solve(2, [RelativeRotation(0, 1, a, 400), RelativeRotation(0, 1, b, 100)])
        .R_w_c
    )
    angle = Rotation.from_matrix(out[1]).as_rotvec()[2]
    assert angle == pytest.approx(0.1 + 0.1 * 1 / 5, abs=1e-4)  # weights 4 : 1


def test_gyro_fusion_cuts_the_error_of_the_chain():
    """Edges with 0.3 deg noise, a 200 Hz gyro with a constant bias and white noise."""
    from eas_vo.types import ImuSeries

    rng = np.random.default_rng(9)
    t_imu = np.arange(0.0, 6.0, 0.005)
    omega_c = np.cumsum(rng.normal(0, 0.05, (len(t_imu), 3)), axis=0)  # smooth body rates [rad/s]
    exact = ImuSeries(t_imu, np.zeros_like(omega_c), omega_c)  # rates linear between readings
    R_imu = np.empty((len(t_imu), 3, 3))
    R_imu[0] = np.eye(3)
    for s in range(1, len(t_imu)):
        R_imu[s] = R_imu[s - 1] @ gyro_rotation(exact, t_imu[s - 1], t_imu[s])
    frames = np.arange(0, len(t_imu) - 1, 10)  # 20 Hz frames on IMU sample times
    R = R_imu[frames]
    bias = np.array([0.01, -0.008, 0.012])
    gyro = omega_c + bias + rng.normal(0, 0.003 * np.sqrt(200), omega_c.shape)
    imu = ImuSeries(t_imu, np.zeros_like(gyro), gyro)
    consecutive = edges_for(R, seed=10, noise_rad=np.radians(0.3))
    with_keyframes = edges_for(R, seed=10, noise_rad=np.radians(0.3), skip=10)
    chain = ape(ChainBackend().solve(len(R), consecutive).R_w_c, R)
    for mode in ("batch", "online"):
        gyro = GtsamConfig(gyro=True, mode=mode)
        # consecutive edges only: the gyro helps, but its bias is barely observable
        assert ape(GtsamBackend(gyro).solve(len(R), consecutive, times=t_imu[frames], imu=imu).R_w_c, R) < 0.85 * chain
        # with multi-frame edges the bias is pinned down (measured 0.05 x the chain)
        fused = ape(GtsamBackend(gyro).solve(len(R), with_keyframes, times=t_imu[frames], imu=imu).R_w_c, R)
        vision_only = ape(GtsamBackend(GtsamConfig(mode=mode)).solve(len(R), with_keyframes).R_w_c, R)
        assert fused <= 0.3 * chain and fused < vision_only, (mode, fused, vision_only, chain)
    # `auto` fuses the gyro when there is one, and is the vision-only graph without
    auto = GtsamBackend(GtsamConfig(gyro="auto"))
    assert not auto.needs_imu
    np.testing.assert_array_equal(
        auto.solve(len(R), with_keyframes, times=t_imu[frames], imu=imu).R_w_c,
        GtsamBackend(GtsamConfig(gyro=True)).solve(len(R), with_keyframes, times=t_imu[frames], imu=imu).R_w_c,
    )
    np.testing.assert_array_equal(
        auto.solve(len(R), with_keyframes, times=t_imu[frames], imu=None).R_w_c,
        GtsamBackend(GtsamConfig()).solve(len(R), with_keyframes).R_w_c,
    )


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_the_gyro_alone_turns_the_frames_by_its_exact_integral(mode):
    """No image edges, a noiseless unbiased gyro whose rate grows linearly about a fixed axis:
    the frames turn by the exact integral (readings are rates at their times, linear in between;
    held until the next one they would lag half a sample: 0.55 deg over this second). Measured
    0.0006 deg: the loose identity edges of frames without a measurement (gap_sigma_rad)."""
    from eas_vo.types import ImuSeries

    axis = np.array([0.6, -0.48, 0.64])
    t_imu = np.arange(0.0, 1.2, 0.005)
    imu = ImuSeries(t_imu, np.zeros((len(t_imu), 3)), 4.0 * t_imu[:, None] * axis)  # 4 rad/s^2
    times = np.arange(0.0113, 1.0, 0.05)
    R = GtsamBackend(GtsamConfig(gyro=True, mode=mode)).solve(len(times), [], times=times, imu=imu).R_w_c
    exact = Rotation.from_rotvec(2.0 * (times[:, None] ** 2 - times[0] ** 2) * axis).as_matrix()
    assert np.degrees(geodesic_angle(R, exact)).max() < 0.01


def test_edge_quality_sets_the_noise_and_a_weak_edge_yields():
    """Two contradicting measurements of one step without covariances: with `covariance` noise
    (from their quality) the one with the small residual and high inlier ratio wins, whatever
    their inlier counts (least squares: a robust kernel would weigh them by their disagreement too)."""
    good, bad = np.eye(3), Rotation.from_rotvec([0.0, 0.05, 0.0]).as_matrix()
    edges = [
        RelativeRotation(0, 1, good, 100, inlier_ratio=0.95, residual_rad=0.001),
        RelativeRotation(0, 1, bad, 300, inlier_ratio=0.4, residual_rad=0.004),
    ]
    backend = GtsamBackend(GtsamConfig(edge_noise="covariance", robust="none"))
    sigma = [np.sqrt(np.linalg.eigvalsh(backend.edge_covariance(e))[-1]) for e in edges]
    assert sigma[0] < sigma[1] / 5
    assert_rotations_close(backend.solve(2, edges).R_w_c[1], good, np.radians(0.2))
    by_inliers = (
        GtsamBackend(GtsamConfig(edge_noise="inliers", robust="none")).solve(2, edges).R_w_c[1]
    )  # one isotropic sigma from the count trusts the count
    assert_rotations_close(by_inliers, bad, np.radians(1.0))


@pytest.mark.parametrize("value", [1, 0, "yes", "on"])
def test_gyro_takes_true_false_or_auto(value):
    """1 and 0 are not booleans here (TOML keeps them apart), and no other word is taken."""
    with pytest.raises(ConfigError, match="gyro = .*; allowed: true, false, auto"):
        GtsamConfig(gyro=value).validate()


def test_the_gyro_model_defaults_to_the_simulated_davis_imu():
    """The graph's gyro noise and bias prior describe the IMU the embedded sequences come from."""
    from eas_vo.datasets.simulator.sensor import ImuModel

    assert (GtsamConfig().gyro_noise, GtsamConfig().gyro_bias_sigma) == (ImuModel().gyro_noise, ImuModel().gyro_bias)


def gyro_rig(seed=9, noise_deg=0.3):
    """A 200 Hz gyro with white noise and 20 Hz frames on its readings, their true rotations
    and consecutive edges with `noise_deg` of noise and 100 inliers."""
    from eas_vo.types import ImuSeries

    rng = np.random.default_rng(seed)
    t_imu = np.arange(0.0, 4.0, 0.005)
    omega = 1.0 + np.cumsum(rng.normal(0, 0.05, (len(t_imu), 3)), axis=0)
    exact = ImuSeries(t_imu, np.zeros_like(omega), omega)
    frames = np.arange(0, len(t_imu) - 1, 10)
    R = np.empty((len(frames), 3, 3))
    R[0] = np.eye(3)
    for k in range(1, len(frames)):
        R[k] = R[k - 1] @ gyro_rotation(exact, t_imu[frames[k - 1]], t_imu[frames[k]])
    noisy = ImuSeries(t_imu, np.zeros_like(omega), omega + rng.normal(0, 0.003 * np.sqrt(200), omega.shape))
    return t_imu[frames], R, noisy, edges_for(R, seed=seed + 1, noise_rad=np.radians(noise_deg))


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_a_repeated_frame_time_gets_no_gyro_factor_and_the_graph_still_fuses(mode):
    """Frame 10 repeats frame 9 (its timestamp and view; the tracker measures nothing there): no
    factor over no time, and the rest is fused as without it, in batch (which returned the
    chain) and online (which raised gtsam's IndeterminateSystemException)."""
    times, R, imu, _ = gyro_rig()
    times, R = np.insert(times, 10, times[9]), np.insert(R, 10, R[9], axis=0)
    edges = [e for e in edges_for(R, seed=10, noise_rad=np.radians(0.3)) if e.j != 10]
    solved = GtsamBackend(GtsamConfig(gyro=True, mode=mode)).solve(len(R), edges, times=times, imu=imu)
    fused = ape(solved.R_w_c, R)
    chain = ape(ChainBackend().solve(len(R), edges).R_w_c, R)
    assert fused < 0.5 * chain and solved.warnings == (), (fused, chain)


def test_a_gyro_glitch_within_range_never_overrides_confident_images():
    """One reading 30 rad/s off (within a MEMS gyro's range): the interval it falls in is left
    out (a gate, warned); every frame pair then follows the images and the gyro elsewhere."""
    from eas_vo.types import ImuSeries

    times, R, imu, edges = gyro_rig()
    rates = imu.gyro.copy()
    glitch = int(np.searchsorted(imu.t, times[20])) + 3  # inside frame interval 20 -> 21
    rates[glitch, 2] += 30.0
    fused = GtsamBackend(GtsamConfig(gyro=True)).solve(len(R), edges, times=times, imu=ImuSeries(imu.t, imu.acc, rates))

    def step(R_w, k):
        return R_w[k - 1].T @ R_w[k]

    assert np.degrees(geodesic_angle(step(fused.R_w_c, 21), step(R, 21))) < 1.0
    assert len(fused.warnings) == 1 and "left out of 1 frame interval" in fused.warnings[0]
    assert "frame 21" in fused.warnings[0]
    right = GtsamBackend(GtsamConfig(gyro=True)).solve(len(R), edges, times=times, imu=imu)
    assert right.warnings == ()  # a right gyro is never gated by the images' noise


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_a_solver_that_fails_is_a_warning_and_the_chain(mode, monkeypatch):
    times, R, imu, edges = gyro_rig()
    backend = GtsamBackend(GtsamConfig(gyro=True, mode=mode))

    def fails(*args):
        raise RuntimeError("Indeterminant linear system detected while working near variable 7")

    monkeypatch.setattr(backend, f"_{mode}", fails)
    out = backend.solve(len(R), edges, times=times, imu=imu)
    assert_rotations_close(out.R_w_c, ChainBackend().solve(len(R), edges).R_w_c, 1e-12)
    assert out.warnings == (
        f"the pose graph could not be solved ({mode}: Indeterminant linear system detected "
        "while working near variable 7): the rotations are the chained measurements, unsmoothed",
    )
    assert out.causal_R_w_c is None
    np.testing.assert_array_equal(out.covariance, chain_covariance(len(R), edges))  # the chain's, as its rotations


def test_levenberg_marquardt_stopped_early_is_said():
    times, R, imu, edges = gyro_rig()
    warnings = GtsamBackend(GtsamConfig(gyro=True, iterations=1)).solve(len(R), edges, times=times, imu=imu).warnings
    assert len(warnings) == 1 and "stopped at backend.iterations = 1" in warnings[0]


def test_levenberg_marquardt_at_its_limit_but_converged_is_not_said():
    """Stopped by backend.iterations where one more step turns no frame by over
    CONVERGED_STEP_RAD: converged for every purpose, no warning; a step that still turns one is said."""
    from eas_vo.backends.gtsam_graph import CONVERGED_STEP_RAD

    times, R, imu, edges = gyro_rig()
    free = GtsamBackend(GtsamConfig(gyro=True, iterations=10_000)).solve(len(R), edges, times=times, imu=imu)
    original = GtsamBackend._next_step_rad
    steps = {}  # the limit -> how far the step after it turns a frame [rad]
    for limit in range(1, 30):
        backend = GtsamBackend(GtsamConfig(gyro=True, iterations=limit))
        backend._next_step_rad = lambda optimizer, R_w_c, limit=limit: steps.setdefault(
            limit, original(optimizer, R_w_c)
        )
        warnings = backend.solve(len(R), edges, times=times, imu=imu).warnings
        if limit not in steps:  # converged by its tolerances before the limit
            break
        assert (steps[limit] > CONVERGED_STEP_RAD) == bool(warnings), (limit, steps)
    assert steps[1] > CONVERGED_STEP_RAD and min(steps.values()) <= CONVERGED_STEP_RAD, steps  # both cases met
    assert free.warnings == ()


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_a_reused_backend_returns_nothing_of_its_previous_solve(mode, monkeypatch):
    """A solve's warnings and causal estimate are its result's alone: the same backend solving
    again (a shorter sequence with a right gyro, after one with a glitch) returns what a new
    backend returns and leaves the first result as it was; a solve that fails then has no
    causal estimate."""
    from eas_vo.types import ImuSeries

    times, R, imu, edges = gyro_rig()
    rates = imu.gyro.copy()
    rates[int(np.searchsorted(imu.t, times[20])) + 3, 2] += 30.0  # a glitch the gate leaves out, warned
    backend = GtsamBackend(GtsamConfig(gyro=True, mode=mode))
    first = backend.solve(len(R), edges, times=times, imu=ImuSeries(imu.t, imu.acc, rates))
    first_causal = None if first.causal_R_w_c is None else first.causal_R_w_c.copy()
    assert len(first.warnings) == 1 and (first_causal is None) == (mode == "batch")

    n = 30
    short = [e for e in edges if e.j < n]
    second = backend.solve(n, short, times=times[:n], imu=imu)
    new = GtsamBackend(GtsamConfig(gyro=True, mode=mode)).solve(n, short, times=times[:n], imu=imu)
    assert second.warnings == new.warnings == ()
    np.testing.assert_array_equal(second.R_w_c, new.R_w_c)
    if mode == "online":
        np.testing.assert_array_equal(second.causal_R_w_c, new.causal_R_w_c)
        np.testing.assert_array_equal(first.causal_R_w_c, first_causal)
    else:
        assert second.causal_R_w_c is None
    assert len(first.warnings) == 1 and "left out of 1 frame interval" in first.warnings[0]

    def fails(*args):
        raise RuntimeError("Indeterminant linear system detected while working near variable 7")

    monkeypatch.setattr(backend, f"_{mode}", fails)
    failed = backend.solve(n, short, times=times[:n], imu=imu)
    assert failed.causal_R_w_c is None and len(failed.warnings) == 1 and "could not be solved" in failed.warnings[0]


def test_gtsams_rot3_marginal_is_the_right_perturbation_in_the_body_frame():
    """BackendResult.covariance is of R_w_c,true = R_w_c Exp(delta), delta in the camera frame:
    GTSAM's marginal of a Rot3 reached through a turned BetweenFactor from an anisotropic prior is
    R_step^T Sigma_0 R_step + Sigma_step (the right perturbation's propagation), not
    Sigma_0 + R_step Sigma_step R_step^T (a left one, in the world frame)."""
    import gtsam

    R_0 = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix()
    R_step = Rotation.from_rotvec([0.9, 0.2, -0.4]).as_matrix()
    S_0, S_step = np.diag([1.0, 4.0, 9.0]) * 1e-4, np.diag([16.0, 1.0, 2.0]) * 1e-4
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorRot3(0, gtsam.Rot3(R_0), gtsam.noiseModel.Gaussian.Covariance(S_0)))
    graph.add(gtsam.BetweenFactorRot3(0, 1, gtsam.Rot3(R_step), gtsam.noiseModel.Gaussian.Covariance(S_step)))
    values = gtsam.Values()
    values.insert(0, gtsam.Rot3(R_0))
    values.insert(1, gtsam.Rot3(R_0 @ R_step))
    marginal = gtsam.Marginals(graph, values).marginalCovariance(1)
    right, left = R_step.T @ S_0 @ R_step + S_step, S_0 + R_step @ S_step @ R_step.T
    np.testing.assert_allclose(marginal, right, atol=1e-15)
    assert np.abs(marginal - left).max() > 1e-4


def anisotropic_chain(n=60, seed=10):
    """Consecutive edges of exact steps (a few degrees each), each with its own anisotropic covariance
    (sigmas 0.02-0.3 deg, above the backend's sigma_floor_rad)."""
    rng = np.random.default_rng(seed)
    R = truth(n, seed)
    edges = []
    for k in range(1, n):
        Q = Rotation.from_rotvec(rng.normal(0, 1.0, 3)).as_matrix()
        cov = Q @ np.diag(rng.uniform(0.0004, 0.005, 3) ** 2) @ Q.T
        edges.append(RelativeRotation(k - 1, k, R[k - 1].T @ R[k], 100, covariance=cov))
    return R, edges


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_the_marginals_of_a_chain_only_graph_are_the_chains_propagation(mode):
    R, edges = anisotropic_chain()
    graph = GtsamBackend(GtsamConfig(mode=mode)).solve(len(R), edges)
    chain = ChainBackend().solve(len(R), edges)
    np.testing.assert_array_equal(chain.covariance, chain_covariance(len(R), edges))
    assert graph.covariance.shape == (len(R), 3, 3) and graph.warnings == ()
    scale = np.linalg.norm(chain.covariance, axis=(1, 2))
    relative = np.linalg.norm(graph.covariance - chain.covariance, axis=(1, 2))[1:] / scale[1:]
    assert relative.max() < 1e-6, relative.max()
    assert np.abs(graph.covariance[0]).max() < 1e-15  # frame 0 held at the identity


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_keyframe_edges_shrink_the_marginals_below_the_chains(mode):
    """Edges from every third frame to the next three (klt's keyframe edges) measure the same motion
    again: every frame's marginal is at most the chain's (in the positive semi-definite order),
    the last frame's well below it."""
    R, edges = anisotropic_chain(seed=11)
    rng = np.random.default_rng(12)
    keyframe = [measure(R, i, j, rng, 0.002) for i in range(0, len(R), 3) for j in range(i + 2, min(i + 4, len(R)))]
    chain = chain_covariance(len(R), edges)
    graph = GtsamBackend(GtsamConfig(mode=mode)).solve(len(R), edges + keyframe).covariance
    smallest = [np.linalg.eigvalsh(chain[k] - graph[k])[0] for k in range(1, len(R))]
    assert min(smallest) > -1e-12
    assert np.trace(graph[-1]) < 0.7 * np.trace(chain[-1])
