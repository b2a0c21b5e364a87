"""APE (Eq. 3): known perturbations, alignment at the first frame, slerp and time offset."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import assert_rotations_close
from eas_vo.evaluation import rotation_errors
from eas_vo.geometry import geodesic_angle, interpolate_poses, quats_from_matrices
from eas_vo.types import PoseSeries


def ground_truth(n=50, seed=0, rate=100.0):
    rng = np.random.default_rng(seed)
    R = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.03, (n, 3)), axis=0)).as_matrix()
    t = np.arange(n) / rate
    return PoseSeries(t, rng.normal(size=(n, 3)), quats_from_matrices(R)), R


def test_ape_of_a_known_perturbation_after_an_unknown_global_rotation():
    gt, R_gt = ground_truth()
    rng = np.random.default_rng(1)
    angles = rng.uniform(0, 0.2, len(R_gt))
    angles[0] = 0.0  # the estimate is aligned at the first frame
    axes = rng.normal(size=(len(R_gt), 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    perturb = Rotation.from_rotvec(axes * angles[:, None]).as_matrix()
    offset = Rotation.from_rotvec([0.5, -1.0, 2.0]).as_matrix()  # estimate in another world frame
    R_est = offset @ R_gt @ perturb
    err = rotation_errors(gt.t, R_est, gt)
    np.testing.assert_allclose(err.ape_rad, angles, atol=1e-9)
    s = err.summary()
    assert s["ape_mean_rad"] == pytest.approx(angles.mean(), abs=1e-9)
    assert s["ape_rmse_rad"] == pytest.approx(np.sqrt(np.mean(angles**2)), abs=1e-9)
    assert s["ape_max_rad"] == pytest.approx(angles.max(), abs=1e-9)


def test_geodesic_angle_is_precise_for_tiny_and_large_angles():
    for angle in (1e-9, 1e-4, 1.0, 3.1):
        R = Rotation.from_rotvec([0, angle, 0]).as_matrix()
        assert geodesic_angle(np.eye(3), R) == pytest.approx(angle, rel=1e-6)


def test_slerp_halfway_between_two_poses():
    R0 = np.eye(3)
    R1 = Rotation.from_rotvec([0, 0, 0.8]).as_matrix()
    gt = PoseSeries(np.array([0.0, 1.0]), np.array([[0.0, 0, 0], [2.0, 0, 0]]), quats_from_matrices(np.stack([R0, R1])))
    valid, R, p = interpolate_poses(gt, np.array([-0.1, 0.5, 1.2]))
    np.testing.assert_array_equal(valid, [False, True, False])
    assert_rotations_close(R[0], Rotation.from_rotvec([0, 0, 0.4]).as_matrix(), 1e-12)
    np.testing.assert_allclose(p[0], [1.0, 0, 0])


def test_time_offset_samples_ground_truth_later():
    gt, R_gt = ground_truth(rate=100.0)
    t_frames = gt.t[:40]
    R_est = R_gt[2:42]  # the estimate is the truth 20 ms later
    assert rotation_errors(t_frames, R_est, gt, time_offset_s=0.02).ape_rad.max() < 1e-9
    assert rotation_errors(t_frames, R_est, gt, time_offset_s=0.0).ape_rad.max() > 1e-3


def test_frames_outside_the_ground_truth_are_not_evaluated():
    gt, R_gt = ground_truth()
    t = np.concatenate([[-1.0], gt.t[:5]])
    R_est = np.concatenate([np.eye(3)[None], R_gt[:5]])
    err = rotation_errors(t, R_est, gt)
    assert err.valid.tolist() == [False] + [True] * 5
    assert err.ape_rad.max() < 1e-9
