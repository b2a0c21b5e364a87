"""The chain backend on known relative rotations."""

import numpy as np
from scipy.spatial.transform import Rotation

from eas_vo.backends.chain import ChainBackend
from eas_vo.types import RelativeRotation
from helpers import assert_rotations_close


def random_trajectory(n, seed=0):
    steps = Rotation.from_rotvec(np.random.default_rng(seed).normal(0, 0.05, (n, 3))).as_matrix()
    R_w_c = np.empty((n, 3, 3))
    R_w_c[0] = np.eye(3)
    for k in range(1, n):
        R_w_c[k] = R_w_c[k - 1] @ steps[k]
    return R_w_c


def consecutive_edges(R_w_c):
    return [RelativeRotation(k - 1, k, R_w_c[k - 1].T @ R_w_c[k]) for k in range(1, len(R_w_c))]


def test_chain_recovers_a_trajectory_from_exact_relative_rotations():
    R_w_c = random_trajectory(200)
    out = ChainBackend().solve(200, consecutive_edges(R_w_c))
    assert out.causal_R_w_c is None and out.warnings == ()  # no causal estimate, nothing falls short
    assert_rotations_close(out.R_w_c, R_w_c, 1e-9)


def test_missing_edges_keep_the_previous_rotation_and_skip_edges_are_ignored():
    R_w_c = random_trajectory(6, seed=1)
    edges = consecutive_edges(R_w_c)
    del edges[2]  # no measurement for frame 3
    edges.append(RelativeRotation(0, 4, np.eye(3)))  # a skip edge: the chain must ignore it
    out = ChainBackend().solve(6, edges).R_w_c
    assert_rotations_close(out[:3], R_w_c[:3], 1e-12)
    assert_rotations_close(out[3], out[2], 1e-12)
    assert_rotations_close(out[4], out[3] @ (R_w_c[3].T @ R_w_c[4]), 1e-12)


def test_chain_order_is_right_multiplication():
    a = Rotation.from_rotvec([0.3, 0, 0]).as_matrix()
    b = Rotation.from_rotvec([0, 0.4, 0]).as_matrix()
    out = ChainBackend().solve(3, [RelativeRotation(0, 1, a), RelativeRotation(1, 2, b)]).R_w_c
    assert_rotations_close(out[2], a @ b, 1e-12)
    assert not np.allclose(a @ b, b @ a)
