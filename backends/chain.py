"""The paper's backend: chain relative rotations frame to frame, no optimisation."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from eas_vo.geometry.uncertainty import chain_covariance, consecutive_steps
from eas_vo.plugins import Backend, BackendResult
from eas_vo.types import ImuSeries, RelativeRotation


def chain_rotations(n_frames: int, edges: Sequence[RelativeRotation]) -> np.ndarray:
    """R_w_ck = R_w_ck-1 @ R_ck-1_ck; a frame without a consecutive edge keeps the previous rotation.

    Edges i->j with j != i + 1 are ignored (geometry.uncertainty.consecutive_steps). Returns
    (n_frames, 3, 3), frame 0 at the identity.
    """
    step = consecutive_steps(edges)
    R_w_c = np.empty((n_frames, 3, 3))
    current = np.eye(3)
    for k in range(n_frames):
        if k in step:
            current = current @ step[k].R_i_j
        R_w_c[k] = current
    return R_w_c


class ChainBackend(Backend):
    """Optimisation-free chaining of consecutive relative rotations (the paper); the covariance
    of each rotation propagated along the chain to first order
    (geometry.uncertainty.chain_covariance)."""

    name = "chain"
    description = "multiply consecutive relative rotations, no optimisation (the paper)"

    def solve(
        self,
        n_frames: int,
        edges: Sequence[RelativeRotation],
        *,
        times: np.ndarray | None = None,
        imu: ImuSeries | None = None,
    ) -> BackendResult:
        return BackendResult(chain_rotations(n_frames, edges), covariance=chain_covariance(n_frames, edges))
