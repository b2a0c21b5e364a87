"""The HDR room: radiance range, dim view, parallax."""

import numpy as np

from eas_vo.datasets.simulator.generate import DAVIS240_CAMERA, camera_rays
from eas_vo.datasets.simulator.motion import HandHeldMotion
from eas_vo.datasets.simulator.scene import Scene


def test_scene_radiance_spans_four_decades_and_the_view_is_mostly_dim():
    scene = Scene(np.random.default_rng(0))
    lit = scene.atlas[scene.atlas > 0]
    assert np.log10(np.percentile(lit, 99.99) / np.percentile(lit, 0.1)) >= 4
    motion = HandHeldMotion(np.random.default_rng(1), 10.0)
    rays = camera_rays(DAVIS240_CAMERA)
    dim_fraction = []
    for t in np.linspace(0, 10, 21):
        R, p = motion.pose(t)
        radiance = scene.render(R[0], p[0], rays, (180, 240))
        dim_fraction.append(np.mean(radiance < 0.03))  # < 0.03 exposes to under ~2.4 grey levels
    assert np.mean(dim_fraction) > 0.6


def test_render_sees_parallax_from_translation():
    scene = Scene(np.random.default_rng(0))
    rays = camera_rays(DAVIS240_CAMERA)
    a = scene.render(np.eye(3), np.zeros(3), rays, (180, 240))
    b = scene.render(np.eye(3), np.array([0.05, 0, 0]), rays, (180, 240))
    assert np.abs(np.log(a + 1e-3) - np.log(b + 1e-3)).mean() > 0.05
