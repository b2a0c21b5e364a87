"""Rotation helpers: the SO(3) exponential scaled (scaled_rotation) and the gyro's rotation over an interval."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.geometry.rotations import geodesic_angle, gyro_rotation, matrix_to_rotvec, rotvec_to_matrix
from eas_vo.types import ImuSeries


def test_gyro_rotation_takes_each_reading_as_the_rate_at_its_time():
    """A constant rate over 0.05 s turns by rate * 0.05 whatever the sampling; a rate growing
    linearly about a fixed axis turns by its exact integral (a reading held until the next one
    would lag half a sample: 0.0025 s * rate here); a step between two readings is a ramp."""
    t = np.arange(0.0, 1.0, 0.005)
    rate = np.array([0.3, -1.2, 2.0])  # rad/s
    constant = ImuSeries(t, np.zeros((len(t), 3)), np.tile(rate, (len(t), 1)))
    assert (
        geodesic_angle(gyro_rotation(constant, 0.1012, 0.1512), Rotation.from_rotvec(rate * 0.05).as_matrix()) < 1e-12
    )
    ramp = ImuSeries(t, np.zeros((len(t), 3)), 20.0 * t[:, None] * rate)  # 20 rate/s
    t0, t1 = 0.4013, 0.4511
    exact = Rotation.from_rotvec(10.0 * (t1**2 - t0**2) * rate).as_matrix()
    assert geodesic_angle(gyro_rotation(ramp, t0, t1), exact) < 1e-12
    step = np.where(t[:, None] < 0.2, 0.0, rate)  # still until 0.195 s, turning from 0.2 s
    stepped = ImuSeries(t, np.zeros((len(t), 3)), step)
    assert geodesic_angle(gyro_rotation(stepped, 0.18, 0.23), Rotation.from_rotvec(rate * 0.0325).as_matrix()) < 1e-12
    # beyond the readings by up to four reading intervals (20 ms) the first or last is held; further, nothing
    held = Rotation.from_rotvec(rate * 0.05).as_matrix()
    assert geodesic_angle(gyro_rotation(constant, -0.01, 0.04), held) < 1e-12
    assert geodesic_angle(gyro_rotation(constant, 0.96, 1.01), held) < 1e-12
    assert gyro_rotation(constant, -0.03, 0.02) is None and gyro_rotation(constant, 0.97, 1.02) is None


@pytest.mark.parametrize("rotvec", [(0.0, 0.0, np.pi / 2), (0.02, -0.03, 0.01), (np.pi, 0.0, 0.0)])
def test_readings_in_the_camera_frame_turn_the_camera_as_seen_from_it(rotvec):
    """An IMU mounted as R_imu_cam sees the camera's rotation R_c0_c1 as R_imu_cam R_c0_c1
    R_imu_cam^T; in_camera_frame undoes that, and shifts its clock onto the frames'."""
    R_imu_cam = Rotation.from_rotvec(rotvec).as_matrix()
    omega_cam = np.array([0.4, 1.1, -0.7])
    t_imu = np.arange(0.0, 1.0, 0.005)
    imu = ImuSeries(
        t_imu, np.tile(R_imu_cam @ [0.0, 9.81, 0.0], (len(t_imu), 1)), np.tile(R_imu_cam @ omega_cam, (len(t_imu), 1))
    )
    cam = imu.in_camera_frame(R_imu_cam, time_offset_s=0.02)
    np.testing.assert_allclose(cam.gyro, np.tile(omega_cam, (len(t_imu), 1)), atol=1e-12)
    np.testing.assert_allclose(cam.acc[0], [0.0, 9.81, 0.0], atol=1e-12)
    np.testing.assert_allclose(cam.t, t_imu - 0.02)
    assert geodesic_angle(gyro_rotation(cam, 0.3, 0.35), Rotation.from_rotvec(omega_cam * 0.05).as_matrix()) < 1e-12


@pytest.mark.parametrize("factor", [0.0, 0.5, 1.0, 2.5])
def test_a_scaled_rotation_turns_about_the_same_axis_by_the_factor(factor):
    from eas_vo.geometry.rotations import scaled_rotation

    R = rotvec_to_matrix(np.array([0.2, -0.4, 0.1]))
    np.testing.assert_allclose(
        matrix_to_rotvec(scaled_rotation(R, factor)), factor * np.array([0.2, -0.4, 0.1]), rtol=0, atol=1e-14
    )
