"""Rotation helpers: the gyro's rotation over an interval."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.geometry.rotations import geodesic_angle, gyro_rotation
from eas_vo.types import ImuSeries


def test_gyro_rotation_integrates_held_readings():
    """A constant rate over 0.05 s turns by rate * 0.05 whatever the sampling; readings are held
    until the next one, so a rate that changes mid-interval counts for its share only."""
    t = np.arange(0.0, 1.0, 0.005)
    rate = np.array([0.3, -1.2, 2.0])  # rad/s
    constant = ImuSeries(t, np.zeros((len(t), 3)), np.tile(rate, (len(t), 1)))
    expected = Rotation.from_rotvec(rate * 0.05).as_matrix()
    assert geodesic_angle(gyro_rotation(constant, 0.1012, 0.1512), expected) < 1e-12
    step = np.where(t[:, None] < 0.2, 0.0, rate)  # still until 0.2 s, then turning
    stepped = ImuSeries(t, np.zeros((len(t), 3)), step)
    assert geodesic_angle(gyro_rotation(stepped, 0.18, 0.23), Rotation.from_rotvec(rate * 0.03).as_matrix()) < 1e-12
    assert gyro_rotation(constant, -0.01, 0.04) is None and gyro_rotation(constant, 0.97, 1.02) is None


@pytest.mark.parametrize("rotvec", [(0.0, 0.0, np.pi / 2), (0.02, -0.03, 0.01), (np.pi, 0.0, 0.0)])
def test_readings_in_the_camera_frame_turn_the_camera_as_seen_from_it(rotvec):
    """An IMU mounted as R_imu_cam sees the camera's rotation R_c0_c1 as R_imu_cam R_c0_c1
    R_imu_cam^T; in_camera_frame undoes that, and shifts its clock onto the frames'."""
    R_imu_cam = Rotation.from_rotvec(rotvec).as_matrix()
    omega_cam = np.array([0.4, 1.1, -0.7])
    t_imu = np.arange(0.0, 1.0, 0.005)
    imu = ImuSeries(t_imu, np.tile(R_imu_cam @ [0.0, 9.81, 0.0], (len(t_imu), 1)), np.tile(R_imu_cam @ omega_cam, (len(t_imu), 1)))
    cam = imu.in_camera_frame(R_imu_cam, time_offset_s=0.02)
    np.testing.assert_allclose(cam.gyro, np.tile(omega_cam, (len(t_imu), 1)), atol=1e-12)
    np.testing.assert_allclose(cam.acc[0], [0.0, 9.81, 0.0], atol=1e-12)
    np.testing.assert_allclose(cam.t, t_imu - 0.02)
    assert geodesic_angle(gyro_rotation(cam, 0.3, 0.35), Rotation.from_rotvec(omega_cam * 0.05).as_matrix()) < 1e-12
