"""The SO(3) exponential compiled for numba kernels (rotations.rotvec_to_matrix's, one rotation
at a time): apart from rotations.py so that importing the rotation helpers does not import numba."""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def exp_so3(d):
    """The rotation matrix of one rotation vector d [rad] (3,), by Rodrigues' formula: the
    compiled exponential for numba kernels (rotvec_to_matrix's, one at a time)."""
    theta = np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    if theta < 1e-300:
        return np.eye(3)
    x, y, z = d[0] / theta, d[1] / theta, d[2] / theta
    c, s = np.cos(theta), np.sin(theta)
    c1 = 1.0 - c
    return np.array(
        [
            [c + c1 * x * x, c1 * x * y - s * z, c1 * x * z + s * y],
            [c1 * x * y + s * z, c + c1 * y * y, c1 * y * z - s * x],
            [c1 * x * z - s * y, c1 * y * z + s * x, c + c1 * z * z],
        ]
    )
