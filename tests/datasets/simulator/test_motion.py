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

