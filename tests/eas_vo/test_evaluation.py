"""APE (Eq. 3): known perturbations, alignment at the first frame, slerp, scoring TUM files,
and the time offset (known answer; the real excerpt)."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.cli.main import main
from eas_vo.evaluation.ape import rotation_errors, tum_rotation_errors
from eas_vo.evaluation.time_offset import estimate_time_offset
from eas_vo.geometry.rotations import geodesic_angle, interpolate_poses, quats_from_matrices
from eas_vo.io.tum import format_tum
from eas_vo.types import PoseSeries, RelativeRotation
from helpers import SHAPES_ROTATION, assert_rotations_close, require


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


def test_frames_in_a_gap_of_the_ground_truth_are_not_scored():
    """Poses every 5 ms but none between 0.8 and 1.2 s: the 20 Hz frames inside the gap are
    left unscored (a pose at a frame's own time scores it), and the run is said to be covered
    under 90 %."""
    gt, R_gt = ground_truth(n=401, rate=200.0)
    keep = (gt.t <= 0.8 + 1e-9) | (gt.t >= 1.2 - 1e-9)
    holed = PoseSeries(gt.t[keep], gt.p_w_c[keep], gt.q_w_c[keep])
    t = np.arange(41) * 0.05
    err = rotation_errors(t, R_gt[::10], holed)
    in_gap = (t > 0.8 + 1e-9) & (t < 1.2 - 1e-9)
    assert in_gap.sum() == 7 and err.valid.tolist() == (~in_gap).tolist()
    assert err.ape_rad.max() < 1e-9
    coverage = err.coverage(t)
    assert coverage["frames_in_ground_truth_gaps"] == 7 and coverage["frames_scored_fraction"] == pytest.approx(34 / 41)
    assert coverage["ground_truth_span_s"] == [0.0, 2.0] and coverage["ground_truth_max_gap_s"] == pytest.approx(0.02)
    (warning,) = err.coverage_warning(t)
    assert "34 of the run's 41 frames" in warning and "7 frames lie in its gaps" in warning


def test_two_poses_far_apart_score_no_frame_between_them():
    gt = PoseSeries(np.array([0.2, 1.3]), np.zeros((2, 3)), np.array([[0, 0, 0, 1.0], [0, 0.3, 0, 0.954]]))
    t = 0.01 + np.arange(40) * 0.05
    assert not rotation_errors(t, np.tile(np.eye(3), (40, 1, 1)), gt).valid.any()


def test_ground_truth_slower_than_the_frames_scores_them_all():
    """10 Hz poses beside 50 Hz frames: 100 ms between poses is within 10 frame intervals."""
    gt, _ = ground_truth(n=21, rate=10.0)
    t = np.arange(101) * 0.02
    err = rotation_errors(t, np.tile(np.eye(3), (101, 1, 1)), gt)
    assert err.valid.all() and err.coverage_warning(t) == []


def test_time_offset_known_answer():
    rng = np.random.default_rng(0)
    t_gt = np.arange(0, 10, 0.005)
    rotvec = np.cumsum(rng.normal(0, 0.01, (len(t_gt), 3)), axis=0)
    rotvec = np.stack([np.convolve(rotvec[:, k], np.ones(20) / 20, mode="same") for k in range(3)], 1)
    R_gt = Rotation.from_rotvec(rotvec).as_matrix()
    gt = PoseSeries(t_gt, np.zeros((len(t_gt), 3)), quats_from_matrices(R_gt))
    t_frames = np.arange(0.5, 9.5, 0.05)
    true_offset = 0.0137
    _, R_true, _ = interpolate_poses(gt, t_frames + true_offset)
    noise = Rotation.from_rotvec(rng.normal(0, 0.0005, (len(t_frames), 3))).as_matrix()
    edges = [RelativeRotation(k - 1, k, R_true[k - 1].T @ R_true[k] @ noise[k]) for k in range(1, len(t_frames))]
    assert estimate_time_offset(t_frames, edges, gt) == pytest.approx(true_offset, abs=0.0005)
    # ground truth over the first 3 of the frames' 9 s: no offset within the search explains half the edges
    short = PoseSeries(t_gt[:600], gt.p_w_c[:600], gt.q_w_c[:600])
    assert estimate_time_offset(t_frames, edges, short) is None
    assert estimate_time_offset(t_frames, edges[:4], gt) is None


def _steps(R_w_c: np.ndarray, noise_rad: float, seed: int) -> list[RelativeRotation]:
    """Consecutive relative rotations of `R_w_c` (N, 3, 3), each with random noise of about `noise_rad`."""
    noise = Rotation.from_rotvec(
        np.random.default_rng(seed).normal(0, noise_rad / np.sqrt(3), (len(R_w_c), 3))
    ).as_matrix()
    return [RelativeRotation(k - 1, k, R_w_c[k - 1].T @ R_w_c[k] @ noise[k]) for k in range(1, len(R_w_c))]


def test_a_time_offset_without_a_clear_best_fit_is_not_an_estimate():
    """A flat cost (a still camera; identical frames while the camera turns; a turn at a
    constant rate, which looks the same at every offset) or a best fit on the search's edge
    (a true offset of 130 ms, beyond the 100 ms searched) is None, never the edge or a
    point of the flat; 2 s at 20 Hz with 0.03 deg of noise, as a short run."""
    t_gt = np.arange(0, 2.5, 0.005)
    t_frames = np.arange(0.25, 2.25, 0.05)
    moving = ground_truth(len(t_gt), seed=3, rate=200.0)[0]
    still = PoseSeries(t_gt, np.zeros((len(t_gt), 3)), np.tile([0.0, 0.0, 0.0, 1.0], (len(t_gt), 1)))
    steady = Rotation.from_rotvec(np.outer(t_gt, [0.3, -0.5, 0.2])).as_matrix()
    steady = PoseSeries(t_gt, np.zeros((len(t_gt), 3)), quats_from_matrices(steady))
    identical = np.tile(np.eye(3), (len(t_frames), 1, 1))
    noise = np.radians(0.03)
    for gt, R_measured in (
        (still, identical),
        (moving, identical),
        (steady, interpolate_poses(steady, t_frames)[1]),
        (moving, interpolate_poses(moving, t_frames + 0.13)[1]),
    ):
        assert estimate_time_offset(t_frames, _steps(R_measured, noise, seed=2), gt) is None
    # the same 2 s of turning, measured on time and 20 ms late: estimated
    for late_s in (0.0, 0.02):
        edges = _steps(interpolate_poses(moving, t_frames + late_s)[1], noise, seed=2)
        assert estimate_time_offset(t_frames, edges, moving) == pytest.approx(late_s, abs=0.001)


def test_auto_time_offset_on_the_real_excerpt(tmp_path, capsys):
    """--time-offset auto finds the excerpt's offset, and the summary line says it was fitted
    on the ground truth the APE is measured against."""
    folder = str(require(SHAPES_ROTATION))
    out = tmp_path / "auto"
    assert (
        main(
            [
                "run",
                "--dataset",
                folder,
                "--frontend",
                "original",
                "--duration",
                "25",
                "--time-offset",
                "auto",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    # The excerpt's README: frames lead ground truth by about 10 ms. Measured: +9.1 ms.
    assert metrics["time_offset_estimated"] and 0.005 < metrics["time_offset_s"] < 0.015
    said = capsys.readouterr().out
    assert (
        f", time offset {metrics['time_offset_s'] * 1e3:+.1f} ms (estimated on the ground truth it scores against), "
        in said
    )


def test_tum_files_are_scored_like_the_run(tmp_path):
    """The per-frame curve `compare` draws from a cell's TUM files equals the run's own errors."""
    gt, R = ground_truth(80, seed=4)
    rng = np.random.default_rng(1)
    R_est = Rotation.from_rotvec(rng.normal(0, 0.02, (80, 3))).as_matrix() @ R
    errors = rotation_errors(gt.t, R_est, gt)
    zeros = np.zeros((80, 3))
    (tmp_path / "est.tum").write_text(format_tum(gt.t, zeros, R_est))
    (tmp_path / "gt.tum").write_text(format_tum(gt.t, gt.p_w_c, errors.R_w_c_gt))
    t, ape = tum_rotation_errors(tmp_path / "est.tum", tmp_path / "gt.tum")
    np.testing.assert_allclose(t, gt.t - gt.t[0], atol=1e-9)
    np.testing.assert_allclose(ape, errors.ape_rad, atol=1e-9)
    assert tum_rotation_errors(tmp_path / "est.tum", tmp_path / "missing.tum") is None


def _path_of_three(seed=0):
    """Ground truth of a camera moved by hand over 0.5 s: three poses about 2 cm apart."""
    rng = np.random.default_rng(seed)
    t = np.array([0.0, 0.25, 0.5])
    p = np.array([[0.0, 0.0, 0.0], [0.02, 0.005, 0.0], [0.03, 0.02, 0.004]])
    return PoseSeries(t, p, Rotation.from_rotvec(rng.normal(0, 0.1, (3, 3))).as_quat())


@pytest.mark.parametrize(
    "align, positions, says",
    [
        (
            "sim3",
            lambda p: p + np.random.default_rng(1).normal(0, 0.01, p.shape),
            "fix the sim3 alignment's rotation only",
        ),
        (
            "se3",
            lambda p: p + np.random.default_rng(1).normal(0, 0.01, p.shape),
            "fix the se3 alignment's rotation only",
        ),
        ("sim3", lambda p: np.array([[10.0, 20, 30], [11, 22, 33], [12, 24, 36 + 1e-9]]), "lie on a line or a point"),
        ("se3", lambda p: 1e200 * (p + 1), "overflow floating point"),
    ],
)
def test_an_alignment_the_positions_cannot_fix_is_refused(align, positions, says):
    """Three poses with the ground truth's rotations: positions off by 1 cm where the path
    spans 2 cm leave the alignment's rotation free (it turned them by 2.9 rad); positions on
    a line to within rounding span no plane; positions of 1e200 m overflow under se3."""
    from eas_vo.evaluation.trajectory import trajectory_ape

    gt = _path_of_three()
    with pytest.raises(ValueError, match=says):
        trajectory_ape(gt, PoseSeries(gt.t, positions(gt.p_w_c), gt.q_w_c), align)


@pytest.mark.parametrize("align", ["sim3", "se3"])
@pytest.mark.parametrize(
    "positions",
    [
        lambda p: np.zeros_like(p),  # eas-vo's own trajectories: rotation only
        lambda p: np.array([[10.0, 20, 30], [11, 22, 33], [12, 24, 36 + 1e-9]]),  # on a line
        lambda p: p + np.random.default_rng(1).normal(0, 0.01, p.shape),  # too little spread
        lambda p: p[:2],  # too few poses
    ],
)
def test_an_alignment_the_positions_cannot_fix_names_the_origin_alignment(align, positions):
    from eas_vo.evaluation.trajectory import trajectory_ape

    gt = _path_of_three()
    p = positions(gt.p_w_c)
    with pytest.raises(ValueError, match=f"{align} alignment.*; to score the rotations alone .*: --align origin$"):
        trajectory_ape(gt, PoseSeries(gt.t[: len(p)], p, gt.q_w_c[: len(p)]), align)
    assert (
        trajectory_ape(gt, PoseSeries(gt.t[: len(p)], p, gt.q_w_c[: len(p)]), "origin").summary()["ape_rot_mean_rad"]
        < 1e-9
    )


def test_an_alignment_needs_its_least_poses_and_reaches_any_finite_scale():
    from eas_vo.evaluation.trajectory import trajectory_ape

    gt = _path_of_three()
    with pytest.raises(ValueError, match="origin alignment needs at least 2"):
        trajectory_ape(gt, PoseSeries(gt.t[:1], gt.p_w_c[:1], gt.q_w_c[:1]), "origin")
    with pytest.raises(ValueError, match="sim3 alignment needs at least 3"):
        trajectory_ape(gt, PoseSeries(gt.t[:2], gt.p_w_c[:2], gt.q_w_c[:2]), "sim3")
    huge = trajectory_ape(gt, PoseSeries(gt.t, 1e200 * (gt.p_w_c + 1), gt.q_w_c), "sim3")
    assert huge.scale == pytest.approx(1e-200, rel=1e-9) and huge.summary()["ape_trans_mean_m"] < 1e-12
    near = trajectory_ape(
        gt, PoseSeries(gt.t, gt.p_w_c + np.random.default_rng(1).normal(0, 1e-4, (3, 3)), gt.q_w_c), "sim3"
    )
    assert near.summary()["ape_rot_mean_rad"] < 0.05


def _constant_rotation_run(omega, drift_rad_s, error_rad_s, n=101, rate_hz=20.0):
    """Ground truth turning at `omega` [rad/s] (camera frame); an estimate whose edges measure
    omega + error_rad_s and whose trajectory drifts about z at drift_rad_s (known answers)."""
    from eas_vo.evaluation.ape import rotation_errors
    from eas_vo.geometry.rotations import quats_from_matrices, rotvec_to_matrix
    from eas_vo.types import PoseSeries, RelativeRotation

    t = np.arange(n) / rate_hz
    gt_t = np.arange(0, t[-1] + 0.5, 0.005)
    R_gt = rotvec_to_matrix(gt_t[:, None] * omega)
    gt = PoseSeries(gt_t, np.zeros((len(gt_t), 3)), quats_from_matrices(R_gt))
    R_est = rotvec_to_matrix(t[:, None] * omega) @ rotvec_to_matrix(t[:, None] * np.array([0.0, 0.0, drift_rad_s]))
    edges = [RelativeRotation(k - 1, k, rotvec_to_matrix((omega + error_rad_s) / rate_hz)) for k in range(1, n)]
    return t, rotation_errors(t, R_est, gt), edges


def test_angular_velocity_and_rpe_errors_have_known_answers():
    from eas_vo.evaluation.motion import motion_errors

    omega = np.radians([0.0, 0.0, 90.0])  # about z, so the drift about z adds to it exactly
    t, errors, edges = _constant_rotation_run(omega, np.radians(2.0), np.radians([3.0, 0.0, 4.0]))
    m = motion_errors(t, errors, edges)
    assert m["omega_pairs"] == 100
    assert m["omega_rms_x_deg_s"] == pytest.approx(3.0, abs=1e-6)
    assert m["omega_rms_y_deg_s"] == pytest.approx(0.0, abs=1e-6)
    assert m["omega_rms_z_deg_s"] == pytest.approx(4.0, abs=1e-6)
    assert m["omega_rms_deg_s"] == pytest.approx(5.0, abs=1e-6)
    assert m["rpe_pairs"] == 81  # frames 0-80 of 0-100 have one 1 s (20 frames) later
    assert m["rpe_1s_mean_deg"] == pytest.approx(2.0, abs=1e-6) and m["rpe_1s_rmse_deg"] == pytest.approx(2.0, abs=1e-6)


def test_motion_errors_say_none_where_nothing_compares():
    from eas_vo.evaluation.motion import motion_errors

    t, errors, _ = _constant_rotation_run(np.zeros(3), 0.0, np.zeros(3), n=10)
    m = motion_errors(t, errors, [])
    assert (
        m["omega_pairs"] == 0 and m["omega_rms_deg_s"] is None and m["rpe_pairs"] == 0 and m["rpe_1s_mean_deg"] is None
    )
