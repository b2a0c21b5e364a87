"""The compiled SO(3) exponential against OpenCV's Rodrigues and scipy."""

import numpy as np

from eas_vo.geometry.rotations import rotvec_to_matrix


def test_the_compiled_exponential_is_rodrigues_formula_as_opencv_and_scipy_compute_it():
    """exp_so3 (for numba kernels) against OpenCV's Rodrigues and scipy (rotvec_to_matrix), from
    no rotation through tiny ones to beyond a half turn."""
    import cv2

    from eas_vo.geometry.compiled import exp_so3

    for d in ([0.0, 0.0, 0.0], [1e-12, 0.0, -2e-12], [0.01, -0.02, 0.005], [0.5, 1.0, -2.0], [3.0, -1.0, 0.5]):
        np.testing.assert_allclose(exp_so3(np.array(d)), cv2.Rodrigues(np.array(d))[0], rtol=0, atol=1e-15)
        np.testing.assert_allclose(exp_so3(np.array(d)), rotvec_to_matrix(np.array(d)), rtol=0, atol=1e-15)
