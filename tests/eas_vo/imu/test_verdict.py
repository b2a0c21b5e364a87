"""The IMU's checks: what its readings alone refuse (known answers on made gyros), and the
images' verdict on a gyro from exact frame-to-frame rotations."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo.errors import EasVoError
from eas_vo.geometry.rotations import gyro_rotation, matrix_to_rotvec, rotvec_to_matrix
from eas_vo.imu.readings import MAX_GYRO_RAD_S, check_readings
from eas_vo.imu.verdict import CONFIDENT_INLIERS, MIN_JUDGED_PAIRS, judge_gyro
from eas_vo.types import ImuSeries, RelativeRotation

FRAMES = np.arange(0.0, 2.0, 0.05)  # 20 Hz


def gyro(t=None, seed=0) -> ImuSeries:
    """A 200 Hz gyro turning about 1 rad/s about slowly changing axes, with white noise."""
    t = np.arange(-0.1, 2.1, 0.005) if t is None else t
    rng = np.random.default_rng(seed)
    rates = np.column_stack([np.sin(2.0 * t), 0.8 * np.cos(1.3 * t), 0.5 + 0.3 * np.sin(0.7 * t)])
    return ImuSeries(t, np.zeros_like(rates), rates + rng.normal(0, 0.01, rates.shape))


def changed(imu: ImuSeries, t=None, rates=None) -> ImuSeries:
    return ImuSeries(imu.t if t is None else t, imu.acc, imu.gyro if rates is None else rates)


def test_a_right_gyro_passes_without_warning():
    assert check_readings(gyro(), FRAMES, "seq", 0.0) == []


def spiked(imu):
    rates = imu.gyro.copy()
    rates[200, 1] = 1000.0
    return changed(imu, rates=rates)


@pytest.mark.parametrize(
    "make, said",
    [
        (lambda imu: changed(imu, rates=np.degrees(imu.gyro) * 40), "faster than any MEMS gyro"),  # deg/s, fast
        (spiked, "reading 200 (t=0.900000 s)"),
        (lambda imu: changed(imu, rates=imu.gyro * 1e6), "rates must be in rad/s"),
        (lambda imu: changed(imu, rates=np.zeros_like(imu.gyro)), "stuck or not connected"),
        (lambda imu: changed(imu, rates=np.ones_like(imu.gyro)), "stuck or not connected"),
        (lambda imu: ImuSeries(imu.t[::200], imu.acc[::200], imu.gyro[::200]), "less often than the frames"),
        (lambda imu: changed(imu, t=imu.t * 1e6), "timestamps in microseconds"),
        (lambda imu: changed(imu, t=imu.t * 1e9), "timestamps in nanoseconds"),
        (lambda imu: ImuSeries(imu.t[30:32], imu.acc[30:32], imu.gyro[30:32]), "measures none of the window's 39"),
        (lambda imu: changed(imu, t=imu.t - 100.0), "measures none of the window's 39"),
        (lambda imu: ImuSeries(imu.t[:1], imu.acc[:1], imu.gyro[:1]), "holds 1 reading"),
    ],
)
def test_readings_that_cannot_be_right_are_refused(make, said):
    with pytest.raises(EasVoError, match="^seq: the IMU") as refused:
        check_readings(make(gyro()), FRAMES, "seq", 0.0)
    assert said in str(refused.value) and "\n" not in str(refused.value)


def test_the_widest_mems_range_is_accepted_and_one_more_refused():
    imu = gyro()
    rates = imu.gyro.copy()
    rates[100, 0] = MAX_GYRO_RAD_S
    assert check_readings(changed(imu, rates=rates), FRAMES, "seq", 0.0) == []
    rates[100, 0] = -1.01 * MAX_GYRO_RAD_S
    with pytest.raises(EasVoError, match="reading 100"):
        check_readings(changed(imu, rates=rates), FRAMES, "seq", 0.0)


def test_a_gyro_that_misses_part_of_the_window_is_a_warning_counting_what_it_measures():
    imu = gyro()
    keep = (imu.t < 0.5) | (imu.t > 1.0)  # 0.5 s without readings
    warnings = check_readings(ImuSeries(imu.t[keep], imu.acc[keep], imu.gyro[keep]), FRAMES, "seq", 0.25)
    # the 12 frame intervals from [0.45, 0.5] to [1.0, 1.05] cross the gap
    assert len(warnings) == 1 and "measures 27 of the window's 39 frame intervals" in warnings[0]
    assert "run.imu_time_offset_s = 0.25" in warnings[0]


def test_covered_follows_the_gaps_and_the_ends():
    t = np.r_[np.arange(0.0, 1.0, 0.005), np.arange(1.1, 2.0, 0.005)]
    imu = ImuSeries(t, np.zeros((len(t), 3)), np.zeros((len(t), 3)))
    t0 = np.array([0.0, 0.5, 0.95, 1.05, 1.5, 1.99, -0.1, -0.01, 0.6])
    t1 = np.array([0.05, 0.55, 1.0, 1.12, 1.55, 2.01, 0.0, 0.0, 0.5])
    # the last reading's hold (up to four intervals past it) counts; a 0.105 s gap and t1 < t0 do not
    np.testing.assert_array_equal(imu.covered(t0, t1), [1, 1, 0, 0, 1, 1, 0, 1, 0])
    assert gyro_rotation(imu, 0.95, 1.0) is None and gyro_rotation(imu, 0.5, 0.55) is not None


def edges_from(imu: ImuSeries, inliers=100, skip=()):
    """Exact consecutive rotations between FRAMES as the gyro measures them."""
    return [
        RelativeRotation(k - 1, k, gyro_rotation(imu, FRAMES[k - 1], FRAMES[k]), inliers)
        for k in range(1, len(FRAMES))
        if k not in skip
    ]


def test_the_images_agree_with_a_right_gyro_and_contradict_wrong_ones():
    imu = gyro()
    right = judge_gyro(FRAMES, edges_from(imu), imu)
    assert right.can_tell and not right.contradicts and right.use == "used"
    assert right.judged == len(FRAMES) - 1 and right.disagreeing == 0
    swap = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    wrong = {
        "deg/s": changed(imu, rates=np.degrees(imu.gyro)),
        "zeros": changed(imu, rates=imu.gyro * 0),
        "flipped": changed(imu, rates=-imu.gyro),
        "swapped": changed(imu, rates=imu.gyro @ swap),
        "late by 0.4 s": changed(imu, t=imu.t - 0.4),
    }
    for name, bad in wrong.items():
        verdict = judge_gyro(FRAMES, edges_from(imu), bad)
        assert verdict.contradicts and verdict.use == "not used", name
        assert "the gyro is not used" in verdict.warnings(True, [])[0]


def test_the_images_say_when_they_cannot_tell():
    imu = gyro()
    few = judge_gyro(FRAMES, edges_from(imu, inliers=CONFIDENT_INLIERS - 1), imu)
    assert not few.can_tell and few.use == "used unchecked" and few.judged == 0
    some = judge_gyro(FRAMES, edges_from(imu, skip=range(MIN_JUDGED_PAIRS, 40)), changed(imu, rates=-imu.gyro))
    assert some.judged == MIN_JUDGED_PAIRS - 1 and not some.contradicts
    assert "used unchecked" in some.warnings(False, [])[0]


@pytest.mark.parametrize(
    "scale, bias, verdict",
    [
        (1.0, 0.0, "used"),
        (1.03, 0.01, "used"),  # within a MEMS gyro's tolerance and the graph's prior
        (0.7, 0.0, "not used"),
        (1.3, 0.0, "not used"),
        (1.0, 0.25, "not used"),
    ],
)
def test_a_gyro_turning_too_far_or_reading_a_constant_bias_is_contradicted(scale, bias, verdict):
    imu = gyro()
    edges = edges_from(imu)
    wrong = changed(imu, rates=imu.gyro * scale + np.array([bias, -bias, bias]) / np.sqrt(3))
    judged = judge_gyro(FRAMES, edges, wrong)
    assert judged.use == verdict and judged.scale == pytest.approx(scale, abs=0.01)
    assert judged.bias_rad_s == pytest.approx(bias, abs=0.01)
    if verdict == "not used":
        assert ("times as far" if scale != 1.0 else "rad/s (+-") in judged.warnings(False, [])[0]


@pytest.mark.parametrize("focal_factor", [0.5, 1.4])
def test_images_one_scale_off_the_gyro_name_the_focal_length_first_not_the_gyros_units_or_axes(focal_factor):
    """Images measured with the focal length focal_factor times the true one read rotations
    across the optical axis (x, y) 1 / focal_factor times too large: the rates alone cannot tell
    that from a gyro off in scale, so the two are not fused, and the warning names the camera's
    focal length first, not the gyro's units, signs, axes or clock."""
    imu = gyro()
    edges = [
        RelativeRotation(
            e.i, e.j, rotvec_to_matrix(matrix_to_rotvec(e.R_i_j) * [1 / focal_factor, 1 / focal_factor, 1]), e.inliers
        )
        for e in edges_from(imu)
    ]
    verdict = judge_gyro(FRAMES, edges, imu)
    assert verdict.scaled_alike and verdict.use == "not used"
    (said,) = verdict.warnings(False, [])
    assert "focal length first" in said and f"looks {1 / verdict.scale:.2f} times" in said
    assert "Check its units" not in said


def test_a_gyro_one_unit_factor_off_is_still_not_used():
    """Rates in deg/s read as rad/s, on motion slow enough that no reading exceeds a MEMS range."""
    imu = gyro()
    slow = changed(imu, rates=imu.gyro * 0.02)
    verdict = judge_gyro(FRAMES, edges_from(slow), changed(slow, rates=np.degrees(slow.gyro)))
    assert verdict.scale_off and not verdict.scaled_alike and verdict.use == "not used"


def test_a_fit_over_under_a_second_does_not_refute_the_gyro_but_a_wrong_sign_does():
    """Over 0.95 s (20 frames) a bias or scale beyond the thresholds may be the images' own
    systematic error: the gyro is used and the warning says the span is too short; a sign flip
    disagrees in every pair and is refused over any span."""
    imu = gyro()
    second = FRAMES[:20]
    edges = [e for e in edges_from(imu) if e.j < len(second)]
    biased = changed(imu, rates=imu.gyro + np.array([0.25, -0.25, 0.25]) / np.sqrt(3))
    short = judge_gyro(second, edges, biased)
    assert short.bias_off and short.judged_span_s < 1.0 and not short.contradicts and short.use == "used"
    assert any("too short to tell" in w for w in short.warnings(False, []))
    assert judge_gyro(FRAMES, edges_from(imu), biased).contradicts  # the same gyro over 1.95 s
    assert judge_gyro(second, edges, changed(imu, rates=-imu.gyro)).use == "not used"


def still_gyro(seed=1) -> ImuSeries:
    """A 200 Hz gyro on a still camera: the noise model's white noise and a constant bias."""
    from eas_vo.imu.verdict import GYRO_BIAS_RAD_S, GYRO_NOISE_DENSITY

    t = np.arange(-0.1, 2.1, 0.005)
    rng = np.random.default_rng(seed)
    rates = rng.normal(0, GYRO_BIAS_RAD_S, 3) + rng.normal(0, GYRO_NOISE_DENSITY * np.sqrt(200.0), (len(t), 3))
    return ImuSeries(t, np.zeros_like(rates), rates)


def sigma_edges(imu: ImuSeries, omega, sigma_rad: float, seed=2, noise=0.0) -> list:
    """Consecutive edges over FRAMES turning at `omega` [rad/s] past the gyro's rotation, with
    per-axis Gaussian errors of `noise` times their stated sigma."""
    rng = np.random.default_rng(seed)
    out = []
    for i, (t0, t1) in enumerate(zip(FRAMES[:-1], FRAMES[1:])):
        turn = np.asarray(omega) * (t1 - t0) + rng.normal(0, noise * sigma_rad, 3)
        R = gyro_rotation(imu, t0, t1) @ Rotation.from_rotvec(turn).as_matrix()
        out.append(RelativeRotation(i, i + 1, R, inliers=40000, covariance=sigma_rad**2 * np.eye(3)))
    return out


def test_the_noise_model_is_the_simulated_imus_and_the_pose_graphs_and_the_quantile_chi_squares():
    from scipy.stats import chi2

    from eas_vo.backends.gtsam_graph import GtsamConfig
    from eas_vo.datasets.simulator.sensor import ImuModel
    from eas_vo.imu.verdict import CHI2_3_999, GYRO_BIAS_RAD_S, GYRO_NOISE_DENSITY

    assert (GYRO_NOISE_DENSITY, GYRO_BIAS_RAD_S) == (ImuModel().gyro_noise, ImuModel().gyro_bias)
    assert (GYRO_NOISE_DENSITY, GYRO_BIAS_RAD_S) == (GtsamConfig().gyro_noise, GtsamConfig().gyro_bias_sigma)
    assert CHI2_3_999 == pytest.approx(chi2.ppf(0.999, 3), abs=1e-3)


@pytest.mark.parametrize(
    "omega_deg_s, sigma_deg, flagged",
    [
        ((0.0, 12.0, 0.0), 0.05, 39),  # 0.6 deg a pair against sigma 0.05: each pair alone
        ((0.0, 6.0, 0.0), 0.1, 39),  # 0.3 deg a pair, under 3 sigma each, all in one direction: the stretch
        ((0.0, 0.0, 0.0), 0.1, 0),  # the events agree with the still gyro
    ],
)
def test_edges_turning_while_the_gyro_reads_still_are_found_alone_or_over_a_stretch(omega_deg_s, sigma_deg, flagged):
    from eas_vo.imu.verdict import still_gyro_pairs

    imu = still_gyro()
    compared, still = still_gyro_pairs(FRAMES, sigma_edges(imu, np.radians(omega_deg_s), np.radians(sigma_deg)), imu)
    assert compared == len(FRAMES) - 1 and len(still) == flagged


def test_edges_erring_by_their_own_sigma_are_rarely_flagged():
    """Per-axis Gaussian errors of the stated sigma: under 1 % of the pairs (the per-pair test's
    rate is 0.1 %; over a stretch, a pair must also exceed the noise's mean)."""
    from eas_vo.imu.verdict import still_gyro_pairs

    counts = []
    for seed in range(10):
        imu = still_gyro(seed)
        counts.append(len(still_gyro_pairs(FRAMES, sigma_edges(imu, np.zeros(3), np.radians(0.1), seed, 1.0), imu)[1]))
    assert sum(counts) <= 0.01 * 10 * (len(FRAMES) - 1), counts


def test_a_turning_gyro_is_never_still_and_edges_without_a_sigma_are_not_compared():
    from eas_vo.imu.verdict import still_gyro_pairs

    imu = gyro()
    assert still_gyro_pairs(FRAMES, sigma_edges(imu, np.radians([0, 30.0, 0]), np.radians(0.05)), imu)[1] == []
    assert still_gyro_pairs(FRAMES, edges_from(still_gyro()), still_gyro()) == (0, [])


def test_a_moving_scene_before_a_still_gyro_judges_nothing_and_is_said_in_one_line():
    imu = still_gyro()
    verdict = judge_gyro(FRAMES, sigma_edges(imu, np.radians([0, 30.0, 0]), np.radians(0.05)), imu)
    assert verdict.judged == 0 and not verdict.contradicts and len(verdict.still) == len(FRAMES) - 1
    lines = [w for w in verdict.warnings(False, []) if "gyro reads still" in w]
    assert len(lines) == 1 and "frames 1-39" in lines[0] and "1.50 deg apart" in lines[0]
