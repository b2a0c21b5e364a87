"""The gyro's axes and clock fitted against the tracked rotations: known rotations, mirrored axes, clock shifts, and a fit that knows its own uncertainty."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.geometry.rotations import geodesic_angle, gyro_rotation
from eas_vo.imu.fit import imu_agreement
from eas_vo.types import ImuSeries, RelativeRotation


@pytest.mark.parametrize("mirrored", [False, True])
@pytest.mark.parametrize(
    "R_imu_cam",
    [
        np.eye(3),
        Rotation.from_rotvec([0, 0, np.pi / 2]).as_matrix(),
        Rotation.from_rotvec([0.1, -0.25, 0.05]).as_matrix(),
    ],
)
def test_imu_agreement_finds_how_the_gyro_is_turned(R_imu_cam, mirrored):
    """A 200 Hz gyro mounted as R_imu_cam (white noise, constant bias), its axes mirrored (rates
    negated) or not, read as if mounted at the identity; 20 Hz tracked rotations with 0.2 deg
    noise, 3 % too small (lagging events), and a third of them replaced by random rotations: the
    fit finds R_imu_cam within 1 deg, whether it is mirrored, and tells the failed third apart."""
    rng = np.random.default_rng(4)
    t_imu = np.arange(0.0, 10.0, 0.005)
    omega_cam = np.stack(
        [np.convolve(rng.normal(0, 2.0, len(t_imu)), np.ones(40) / 40 * 6, mode="same") for _ in range(3)], 1
    )
    sign = -1.0 if mirrored else 1.0
    gyro = (
        sign * omega_cam @ R_imu_cam.T
        + np.array([0.01, -0.005, 0.008])
        + rng.normal(0, 0.003 * np.sqrt(200), omega_cam.shape)
    )
    imu = ImuSeries(t_imu, np.zeros_like(gyro), gyro).in_camera_frame(np.eye(3), 0.0)
    truth = ImuSeries(t_imu, np.zeros_like(omega_cam), omega_cam)
    t = np.arange(0.2, 9.8, 0.05)
    edges, failed = [], rng.random(len(t)) < 1 / 3
    for k in range(1, len(t)):
        step = Rotation.from_matrix(gyro_rotation(truth, t[k - 1], t[k])).as_rotvec() * 0.97
        if failed[k]:
            step = rng.normal(0, 0.2, 3)
        R = Rotation.from_rotvec(step) * Rotation.from_rotvec(rng.normal(0, np.radians(0.2) / np.sqrt(3), 3))
        edges.append(RelativeRotation(k - 1, k, R.as_matrix()))
    agreement = imu_agreement(t, edges, imu)
    assert np.degrees(geodesic_angle(agreement.R, R_imu_cam)) < 1.0 and agreement.mirrored == mirrored
    assert 0.55 * agreement.pairs < agreement.agreeing < 0.75 * agreement.pairs
    assert imu_agreement(t[:15], edges[:14], imu) is None  # too few frame pairs to tell


def test_the_axes_fit_knows_its_own_uncertainty():
    """Rotation vectors of about 2 deg with 0.4 deg of white noise per pair (a 2 s sequence
    of weak images): the fit's angle scatters about the truth as its own sigma says (within
    20 % over 400 draws), that sigma shrinks as 1 / sqrt(pairs), and no draw of a right IMU
    comes out AXES_SIGMAS of it off (the pipeline's test for naming a mount)."""
    from eas_vo.geometry.two_view import kabsch
    from eas_vo.imu.fit import _fit_sigma_deg
    from eas_vo.imu.policy import AXES_SIGMAS

    rng = np.random.default_rng(5)
    sigmas = {}
    for pairs in (20, 80):
        angles, said = [], []
        for _ in range(400):
            v = rng.normal(0, np.radians(2.0) / np.sqrt(3), (pairs, 3))
            g = v + rng.normal(0, np.radians(0.4) / np.sqrt(3), v.shape)
            R = kabsch(v, g)
            angles.append(Rotation.from_matrix(R).as_rotvec())
            said.append(_fit_sigma_deg(v @ R.T, g))
        angles = np.degrees(np.array(angles))
        assert np.max(np.linalg.norm(angles, axis=1) / np.array(said)) < AXES_SIGMAS
        sigmas[pairs] = float(np.median(said))
        worst_axis = np.sqrt(np.linalg.eigvalsh(np.cov(angles.T))[-1])
        assert sigmas[pairs] == pytest.approx(worst_axis, rel=0.2), (pairs, sigmas[pairs], worst_axis)
    assert sigmas[20] / sigmas[80] == pytest.approx(2.0, rel=0.2)


def test_a_pan_about_one_axis_never_claims_the_imu_is_turned():
    """A camera that only pans (yaw, 0.2 deg noise, IMU placed right): the fit is free about
    the pan axis and lands anywhere; spread says so and the run stays silent. The same with
    hand-held three-axis motion spreads widely."""
    from eas_vo.imu.policy import GyroSetup, disagreements

    rng = np.random.default_rng(8)
    t_imu = np.arange(0.0, 10.0, 0.005)
    pan = np.convolve(rng.normal(0, 2.0, len(t_imu)), np.ones(40) / 40 * 6, mode="same")
    for axes, spread_ok in ((np.array([0.0, 1.0, 0.0]), False), (None, True)):
        omega = pan[:, None] * axes if axes is not None else np.stack([np.roll(pan, 300 * k) for k in range(3)], 1)
        imu = ImuSeries(t_imu, np.zeros_like(omega), omega + rng.normal(0, 0.003 * np.sqrt(200), omega.shape))
        t = np.arange(0.2, 9.8, 0.05)
        noise = Rotation.from_rotvec(rng.normal(0, np.radians(0.2) / np.sqrt(3), (len(t), 3))).as_matrix()
        truth = ImuSeries(t_imu, np.zeros_like(omega), omega)
        edges = [RelativeRotation(k - 1, k, gyro_rotation(truth, t[k - 1], t[k]) @ noise[k]) for k in range(1, len(t))]
        agreement = imu_agreement(t, edges, imu)
        assert (agreement.spread >= 0.2) == spread_ok, agreement.spread
        assert (
            disagreements(GyroSetup((0.0, 0.0, 0.0), 0.0, False, "eas", "klt", "chain"), agreement, reclocked=False)
            == []
        )


@pytest.mark.parametrize("late_s", [0.0, 0.012, -0.02, 0.035, -0.07])
def test_imu_agreement_finds_how_late_the_gyro_is_stamped(late_s):
    """The gyro's readings stamped `late_s` after the frames' clock, read as if on time: the
    search finds the offset within 1.5 ms, and says reading it so explains the tracked rotations
    clearly better (only when it is off)."""
    rng = np.random.default_rng(5)
    t_true = np.arange(0.0, 10.0, 0.001)
    omega = np.stack(
        [np.convolve(rng.normal(0, 2.0, len(t_true)), np.ones(200) / 200 * 14, mode="same") for _ in range(3)], 1
    )
    truth = ImuSeries(t_true, np.zeros_like(omega), omega)
    gyro = omega + rng.normal(0, 0.003 * np.sqrt(1000), omega.shape)
    imu = ImuSeries(t_true + late_s, np.zeros_like(gyro), gyro).in_camera_frame(np.eye(3), 0.0)
    t = np.arange(0.3, 9.7, 0.045)
    noise = Rotation.from_rotvec(rng.normal(0, np.radians(0.2) / np.sqrt(3), (len(t), 3))).as_matrix()
    edges = [RelativeRotation(k - 1, k, gyro_rotation(truth, t[k - 1], t[k]) @ noise[k]) for k in range(1, len(t))]
    agreement = imu_agreement(t, edges, imu)
    assert agreement.clock_shift_s == pytest.approx(late_s, abs=0.0015)
    gain = agreement.residual_rad / agreement.residual_unshifted_rad
    assert gain < 0.7 if late_s else gain > 0.95
