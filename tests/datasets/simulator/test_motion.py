"""The hand-held motion: speed growth, mostly rotation."""

import numpy as np

from eas_vo.datasets.simulator.motion import HandHeldMotion


def test_motion_speed_grows_and_is_mostly_rotation():
    motion = HandHeldMotion(np.random.default_rng(0), 10.0)
    t = np.linspace(0, 10, 2001)
    speed = np.linalg.norm(motion.angular_velocity(t), axis=1)
    assert speed[t > 7].mean() > 1.5 * speed[t < 3].mean()
    _, p = motion.pose(t)
    assert np.ptp(p, axis=0).max() < 0.2  # centimetres, not metres


def test_a_faster_motion_is_the_same_path_travelled_faster():
    """Without speed growth, speed v at time t is speed 1 at v t: the same poses, v times the
    angular velocity."""
    t = np.linspace(0, 2.5, 501)
    slow = HandHeldMotion(np.random.default_rng(4), 10.0, speed_growth=0.0)
    fast = HandHeldMotion(np.random.default_rng(4), 10.0, speed_growth=0.0, speed=4.0)
    R_fast, p_fast = fast.pose(t)
    R_slow, p_slow = slow.pose(4.0 * t)
    np.testing.assert_allclose(R_fast, R_slow, atol=1e-12)
    np.testing.assert_allclose(p_fast, p_slow, atol=1e-12)
    np.testing.assert_allclose(
        fast.angular_velocity(t), 4.0 * slow.angular_velocity(4.0 * t), atol=1e-4
    )  # central differences


def test_a_scaled_translation_is_the_same_path_its_positions_scaled():
    """translation_scale s: the same rotations, s times the positions and the acceleration
    (what the accelerometer measures)."""
    t = np.linspace(0, 5, 301)
    base = HandHeldMotion(np.random.default_rng(4), 10.0)
    walk = HandHeldMotion(np.random.default_rng(4), 10.0, translation_scale=10.0)
    (R_base, p_base), (R_walk, p_walk) = base.pose(t), walk.pose(t)
    np.testing.assert_array_equal(R_walk, R_base)
    np.testing.assert_allclose(p_walk, 10.0 * p_base, rtol=1e-12)
    np.testing.assert_allclose(walk.acceleration(t), 10.0 * base.acceleration(t), rtol=1e-9, atol=1e-9)
