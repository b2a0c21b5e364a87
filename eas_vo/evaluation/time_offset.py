"""The ground truth's time offset against the frames, estimated from the measured rotations."""

from __future__ import annotations

import numpy as np

from eas_vo.geometry.rotations import geodesic_angle
from eas_vo.types import PoseSeries

#: How far [s] run.time_offset_auto searches for the ground truth's time offset, either way.
OFFSET_SEARCH_S = 0.1


def estimate_time_offset(
    t: np.ndarray, edges, ground_truth: PoseSeries, search_s: float = OFFSET_SEARCH_S
) -> float | None:
    """The offset [s] to add to frame times so that ground truth best explains the measured rotations.

    For a candidate offset d, each measured relative rotation R_i_j is compared with the
    ground truth's between t_i + d and t_j + d; the cost is the mean geodesic error [rad] of
    the best 80 % (robust to tracking failures). A 2 ms grid over [-search_s, search_s] is
    refined to 0.1 ms around its best point. None when it cannot be estimated: fewer than 5
    edges; ground truth spanning fewer than half of them (and 5) at every offset of the grid;
    or no clear best: an offset at either end of the search costs no more than the best
    plus two standard errors of that best cost (a still camera, identical frames, rotation
    at a constant rate: a flat cost; or a best fit on the search's edge, the true offset
    lying beyond it).
    """
    from scipy.spatial.transform import Rotation, Slerp

    t = np.asarray(t, dtype=float)
    edges = [e for e in edges if 0 <= e.i < len(t) and 0 <= e.j < len(t)]
    if len(edges) < 5:
        return None
    i = np.array([e.i for e in edges])
    j = np.array([e.j for e in edges])
    R_meas = np.stack([e.R_i_j for e in edges])
    slerp = Slerp(ground_truth.t, Rotation.from_quat(ground_truth.q_w_c))
    span = (ground_truth.t[0], ground_truth.t[-1])

    def kept_errors(offset: float) -> np.ndarray | None:
        """The best 80 % of the edges' errors [rad] at `offset`; None if too few edges have ground truth."""
        tt = t + offset
        use = (tt[i] >= span[0]) & (tt[j] <= span[1])
        if use.sum() < max(5, len(edges) // 2):
            return None
        R_i = slerp(tt[i[use]]).as_matrix()
        R_j = slerp(tt[j[use]]).as_matrix()
        errors = np.sort(geodesic_angle(np.swapaxes(R_i, 1, 2) @ R_j, R_meas[use]))
        return errors[: int(0.8 * len(errors))]

    def cost(offset: float) -> float:
        kept = kept_errors(offset)
        return np.inf if kept is None else float(kept.mean())

    coarse = np.arange(-search_s, search_s + 1e-9, 0.002)
    costs = np.array([cost(d) for d in coarse])
    if not np.isfinite(costs.min()):
        return None
    best = int(np.argmin(costs))
    kept = kept_errors(coarse[best])
    noise = 2 * kept.std(ddof=1) / np.sqrt(len(kept))
    if min(costs[0], costs[-1]) <= costs[best] + noise:
        return None
    fine = coarse[best] + np.arange(-0.002, 0.002 + 1e-9, 0.0001)
    return float(fine[np.argmin([cost(d) for d in fine])])
