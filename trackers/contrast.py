"""Contrast maximisation (Gallego and Scaramuzza, RA-L 2017): the variance of the image of
warped events as a function of the camera's angular velocity, with its analytic gradient.

An event k at time t_k on the undistorted bearing b_k = (x, y, 1) (normalised image
coordinates, camera frame at t_k) is taken back to the reference time t_ref of its window by
the rotation the camera made in between: b'_k = Exp(omega (t_k - t_ref)) b_k, omega the body
angular velocity [rad/s] (R_w_c(t) = R_w_c(t_ref) Exp(omega (t - t_ref))). b'_k is projected
with the pinhole intrinsics of the image of warped events (IWE) and votes bilinearly into it;
the IWE is smoothed by a Gaussian of sigma_px and its variance is the contrast.

The gradient is exact for the smoothed bilinear image: with I = G * H (H the votes, G the
Gaussian, symmetric with a zero border), dVar/domega = 2 / N_px sum_k grad(B)(x'_k) . dx'_k/domega,
B = G * (I - mean(I)) read bilinearly; dExp(phi) b / dphi = -[Exp(phi) b]x J_l(phi), J_l
SO(3)'s left Jacobian, so the warp is exact at any angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np

from eas_vo import concurrency


@dataclass(frozen=True)
class WarpGrid:
    """The image the events are warped into: an undistorted pinhole view (fx, fy, cx, cy [px])
    of width x height px."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def of(cls, K: np.ndarray, width: int, height: int) -> "WarpGrid":
        return cls(int(width), int(height), float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))


@numba.njit(cache=True, inline="always")
def _warp(x, y, dt, w0, w1, w2, fx, fy, cx, cy, jac, want_jac):
    """Bearing (x, y, 1) at t_ref + dt [s], rotated by Exp(omega dt), projected [px]; with
    `want_jac`, jac (2, 3) = d(pixel)/d(omega). Returns (u, v, ok) (ok: in front of the camera)."""
    p0, p1, p2 = w0 * dt, w1 * dt, w2 * dt
    t2 = p0 * p0 + p1 * p1 + p2 * p2
    if t2 < 0.09:  # |phi| < 0.3 rad: Taylor series to t^6, within 2e-10 of the closed forms
        s_ = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0))  # sin(t) / t
        a_ = 0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0))  # (1 - cos t) / t^2
        c_ = 1.0 / 6.0 - t2 / 120.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0))  # (t - sin t) / t^3
    else:
        th = np.sqrt(t2)
        s_ = np.sin(th) / th
        a_ = (1.0 - np.cos(th)) / t2
        c_ = (th - np.sin(th)) / (t2 * th)
    # R b = b + s [p]x b + a [p]x^2 b   (Rodrigues), b = (x, y, 1)
    cx0 = p1 * 1.0 - p2 * y
    cx1 = p2 * x - p0 * 1.0
    cx2 = p0 * y - p1 * x
    dd0 = p1 * cx2 - p2 * cx1
    dd1 = p2 * cx0 - p0 * cx2
    dd2 = p0 * cx1 - p1 * cx0
    q0 = x + s_ * cx0 + a_ * dd0
    q1 = y + s_ * cx1 + a_ * dd1
    q2 = 1.0 + s_ * cx2 + a_ * dd2
    if q2 <= 1e-6:
        return 0.0, 0.0, False
    iz = 1.0 / q2
    u = fx * q0 * iz + cx
    v = fy * q1 * iz + cy
    if want_jac:
        # dq/dphi = -[q]x J_l(phi), J_l = I + a [p]x + c [p]x^2 = (1 - c t2) I + a [p]x + c p p^T, so
        # a row r of d(pixel)/dq times it is w^T J_l, w = q x r: d w + a (w x p) + c (w . p) p
        d = 1.0 - c_ * t2
        for row in range(2):
            if row == 0:  # d(u)/dq = fx iz (1, 0, -q0 iz)
                r0, r1, r2 = fx * iz, 0.0, -fx * q0 * iz * iz
            else:  # d(v)/dq = fy iz (0, 1, -q1 iz)
                r0, r1, r2 = 0.0, fy * iz, -fy * q1 * iz * iz
            w0 = q1 * r2 - q2 * r1
            w1 = q2 * r0 - q0 * r2
            w2 = q0 * r1 - q1 * r0
            wp = c_ * (w0 * p0 + w1 * p1 + w2 * p2)
            jac[row, 0] = dt * (d * w0 + a_ * (w1 * p2 - w2 * p1) + wp * p0)
            jac[row, 1] = dt * (d * w1 + a_ * (w2 * p0 - w0 * p2) + wp * p1)
            jac[row, 2] = dt * (d * w2 + a_ * (w0 * p1 - w1 * p0) + wp * p2)
    return u, v, True


@numba.njit(cache=True)
def accumulate(x, y, dt, omega, fx, fy, cx, cy, H):
    """Bilinear votes of the warped events into H (zeroed first); returns how many landed."""
    H[:] = 0.0
    h, w = H.shape
    jac = np.empty((2, 3))
    landed = 0
    for k in range(len(x)):
        u, v, ok = _warp(x[k], y[k], dt[k], omega[0], omega[1], omega[2], fx, fy, cx, cy, jac, False)
        if not ok or not (0.0 <= u < w - 1) or not (0.0 <= v < h - 1):
            continue
        i, j = int(v), int(u)
        a, b = u - j, v - i
        H[i, j] += (1 - a) * (1 - b)
        H[i, j + 1] += a * (1 - b)
        H[i + 1, j] += (1 - a) * b
        H[i + 1, j + 1] += a * b
        landed += 1
    return landed


@numba.njit(cache=True)
def gather_gradient(x, y, dt, omega, fx, fy, cx, cy, B):
    """sum_k grad(B read bilinearly)(x'_k) . dx'_k/domega (3,), over the events that landed."""
    h, w = B.shape
    jac = np.empty((2, 3))
    g = np.zeros(3)
    for k in range(len(x)):
        u, v, ok = _warp(x[k], y[k], dt[k], omega[0], omega[1], omega[2], fx, fy, cx, cy, jac, True)
        if not ok or not (0.0 <= u < w - 1) or not (0.0 <= v < h - 1):
            continue
        i, j = int(v), int(u)
        a, b = u - j, v - i
        du = (1 - b) * (B[i, j + 1] - B[i, j]) + b * (B[i + 1, j + 1] - B[i + 1, j])
        dv = (1 - a) * (B[i + 1, j] - B[i, j]) + a * (B[i + 1, j + 1] - B[i, j + 1])
        for m in range(3):
            g[m] += du * jac[0, m] + dv * jac[1, m]
    return g


#: Events per chunk of the kernels split across threads: the chunks' partial sums are added in
#: chunk order, so a result does not depend on how many threads ran them.
CHUNK = 4096
#: A thread takes at least this many chunks: a window of under 2 * MIN_CHUNKS * CHUNK events
#: runs on one, as splitting the default window costs more than it gains (docs/speed.md,
#: "Rotation from events alone (`cmax`)").
MIN_CHUNKS = 8
#: The images a pass can vote into: the whole window's, then its four quadrants' (about the
#: optical axis: x > 0, y > 0; x > 0, y < 0; x < 0, y > 0; x < 0, y < 0).
FULL, QUADRANTS = 1, 2


@numba.njit(cache=True, error_model="numpy", inline="always")
def _series_warp(x, y, dt, w0, w1, w2, fx, fy, cx, cy):
    """_warp's series branch (|omega dt| < 0.3 rad) without branches, so that a loop of it is
    vectorised: (u, v, q2, d(u)/domega (3), d(v)/domega (3)); the same arithmetic as _warp."""
    p0, p1, p2 = w0 * dt, w1 * dt, w2 * dt
    t2 = p0 * p0 + p1 * p1 + p2 * p2
    s_ = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0))
    a_ = 0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0))
    c_ = 1.0 / 6.0 - t2 / 120.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0))
    cx0 = p1 * 1.0 - p2 * y
    cx1 = p2 * x - p0 * 1.0
    cx2 = p0 * y - p1 * x
    dd0 = p1 * cx2 - p2 * cx1
    dd1 = p2 * cx0 - p0 * cx2
    dd2 = p0 * cx1 - p1 * cx0
    q0 = x + s_ * cx0 + a_ * dd0
    q1 = y + s_ * cx1 + a_ * dd1
    q2 = 1.0 + s_ * cx2 + a_ * dd2
    iz = 1.0 / q2
    d = 1.0 - c_ * t2
    # row u: r = fx iz (1, 0, -q0 iz), w = q x r
    r0, r2 = fx * iz, -fx * q0 * iz * iz
    wa, wb, wc = q1 * r2, q2 * r0 - q0 * r2, -q1 * r0
    wp = c_ * (wa * p0 + wb * p1 + wc * p2)
    ju0 = dt * (d * wa + a_ * (wb * p2 - wc * p1) + wp * p0)
    ju1 = dt * (d * wb + a_ * (wc * p0 - wa * p2) + wp * p1)
    ju2 = dt * (d * wc + a_ * (wa * p1 - wb * p0) + wp * p2)
    # row v: r = fy iz (0, 1, -q1 iz)
    r1, r2 = fy * iz, -fy * q1 * iz * iz
    wa, wb, wc = q1 * r2 - q2 * r1, -q0 * r2, q0 * r1
    wp = c_ * (wa * p0 + wb * p1 + wc * p2)
    jv0 = dt * (d * wa + a_ * (wb * p2 - wc * p1) + wp * p0)
    jv1 = dt * (d * wb + a_ * (wc * p0 - wa * p2) + wp * p1)
    jv2 = dt * (d * wc + a_ * (wa * p1 - wb * p0) + wp * p2)
    return fx * q0 * iz + cx, fy * q1 * iz + cy, q2, ju0, ju1, ju2, jv0, jv1, jv2


@numba.njit(cache=True, error_model="numpy")
def _series_one(x, y, dt, w0, w1, w2, fx, fy, cx, cy, U, V, Z, J0, J1, J2, J3, J4, J5):
    """_series_warp of every event by one omega into U, V, Z (u, v, q2) and J0..J5 (d(u, v)/domega).
    (A loop over range(len(x)): LLVM vectorises it, not one over range(lo, hi).)"""
    for k in range(len(x)):
        U[k], V[k], Z[k], J0[k], J1[k], J2[k], J3[k], J4[k], J5[k] = _series_warp(
            x[k], y[k], dt[k], w0, w1, w2, fx, fy, cx, cy
        )


@numba.njit(cache=True, error_model="numpy")
def _series_each(x, y, dt, W0, W1, W2, fx, fy, cx, cy, U, V, Z, J0, J1, J2, J3, J4, J5):
    """The same, each event by its own omega (W0[k], W1[k], W2[k])."""
    for k in range(len(x)):
        U[k], V[k], Z[k], J0[k], J1[k], J2[k], J3[k], J4[k], J5[k] = _series_warp(
            x[k], y[k], dt[k], W0[k], W1[k], W2[k], fx, fy, cx, cy
        )


def warp_events(x, y, dt, label, index, omegas, fx, fy, cx, cy, width, height, uvz, cell, frac, jac) -> None:
    """Every event warped by its own omega (omegas[index[k]], index = max(label, 0); label < 0 and
    several omegas: skipped): cell[k] = i * width + j of the bilinear cell it lands in (-1: it
    does not), frac[:, k] = its offsets (a, b) in the cell, jac[:, k] = d(u, v)/domega (6,); uvz
    (6, N) is scratch. The series (_series_warp) first, vectorised, then _warp's closed forms
    where |omega dt| >= 0.3 rad: the same values as _warp. Chunks of CHUNK events split across
    eas_vo.concurrency's threads (the kernel releases the GIL)."""
    chunks = (len(x) + CHUNK - 1) // CHUNK
    concurrency.split(
        lambda c0, c1: _warp_chunks(
            c0, c1, x, y, dt, label, index, omegas, fx, fy, cx, cy, width, height, uvz, cell, frac, jac
        ),
        chunks,
        MIN_CHUNKS,
    )


@numba.njit(cache=True, nogil=True)
def _warp_chunks(c0, c1, x, y, dt, label, index, omegas, fx, fy, cx, cy, width, height, uvz, cell, frac, jac):
    """warp_events over the events of chunks c0..c1-1."""
    n = len(x)
    several = omegas.shape[0] > 1
    for c in range(c0, c1):
        lo, hi = c * CHUNK, min(n, (c + 1) * CHUNK)
        if several:
            for k in range(lo, hi):
                for m in range(3):
                    uvz[3 + m, k] = omegas[index[k], m]
            _series_each(
                x[lo:hi],
                y[lo:hi],
                dt[lo:hi],
                uvz[3, lo:hi],
                uvz[4, lo:hi],
                uvz[5, lo:hi],
                fx,
                fy,
                cx,
                cy,
                uvz[0, lo:hi],
                uvz[1, lo:hi],
                uvz[2, lo:hi],
                jac[0, lo:hi],
                jac[1, lo:hi],
                jac[2, lo:hi],
                jac[3, lo:hi],
                jac[4, lo:hi],
                jac[5, lo:hi],
            )
        else:
            _series_one(
                x[lo:hi],
                y[lo:hi],
                dt[lo:hi],
                omegas[0, 0],
                omegas[0, 1],
                omegas[0, 2],
                fx,
                fy,
                cx,
                cy,
                uvz[0, lo:hi],
                uvz[1, lo:hi],
                uvz[2, lo:hi],
                jac[0, lo:hi],
                jac[1, lo:hi],
                jac[2, lo:hi],
                jac[3, lo:hi],
                jac[4, lo:hi],
                jac[5, lo:hi],
            )
        J = np.empty((2, 3))
        for k in range(lo, hi):
            if several and label[k] < 0:
                cell[k] = -1
                continue
            r = label[k] if several else 0
            w0, w1, w2 = omegas[r, 0] * dt[k], omegas[r, 1] * dt[k], omegas[r, 2] * dt[k]
            if w0 * w0 + w1 * w1 + w2 * w2 >= 0.09:  # beyond the series
                u, v, ok = _warp(x[k], y[k], dt[k], omegas[r, 0], omegas[r, 1], omegas[r, 2], fx, fy, cx, cy, J, True)
                for m in range(3):
                    jac[m, k] = J[0, m]
                    jac[3 + m, k] = J[1, m]
            else:
                u, v, ok = uvz[0, k], uvz[1, k], uvz[2, k] > 1e-6
            if not ok or not (0.0 <= u < width - 1) or not (0.0 <= v < height - 1):
                cell[k] = -1
                continue
            i, j = int(v), int(u)
            cell[k] = i * width + j
            frac[0, k] = u - j
            frac[1, k] = v - i


@numba.njit(cache=True)
def vote(cell, frac, label, images, which):
    """Bilinear votes of the warped events into images (M, height, width) (zeroed first), in
    event order: into images[0] when `which` has FULL, into images[1 + label] (label >= 0) when
    it has QUADRANTS (the whole window's image then comes first only if it has FULL too).
    Returns how many landed, and each image's box of cells voted into (M, 4): first and last
    row, first and last column (first > last: none)."""
    images[:] = 0.0
    height, width = images.shape[1], images.shape[2]
    first = 1 if which & FULL else 0
    box = np.empty((images.shape[0], 4), np.int64)
    box[:, 0], box[:, 1], box[:, 2], box[:, 3] = height, -1, width, -1
    landed = 0
    for k in range(len(cell)):
        c = cell[k]
        if c < 0:
            continue
        i, j = c // width, c % width
        a, b = frac[0, k], frac[1, k]
        w00, w01, w10, w11 = (1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b
        landed += 1
        if which & FULL:
            H = images[0]
            _grow(box, 0, i, j)
            H[i, j] += w00
            H[i, j + 1] += w01
            H[i + 1, j] += w10
            H[i + 1, j + 1] += w11
        if which & QUADRANTS and label[k] >= 0:
            H = images[first + label[k]]
            _grow(box, first + label[k], i, j)
            H[i, j] += w00
            H[i, j + 1] += w01
            H[i + 1, j] += w10
            H[i + 1, j + 1] += w11
    return landed, box


@numba.njit(cache=True, inline="always")
def _grow(box, m, i, j):
    """Box m of `vote` grown to the bilinear cell (i, j) (rows i, i + 1; columns j, j + 1)."""
    if i < box[m, 0]:
        box[m, 0] = i
    if i + 1 > box[m, 1]:
        box[m, 1] = i + 1
    if j < box[m, 2]:
        box[m, 2] = j
    if j + 1 > box[m, 3]:
        box[m, 3] = j + 1


def gather(cell, frac, jac, label, B, which) -> np.ndarray:
    """The gradient sums of gather_gradient over the warped events, per image of `vote` (M, 3):
    sum_k grad(B_m read bilinearly)(x'_k) . dx'_k/domega; each chunk of CHUNK events summed on
    its own (chunks split across eas_vo.concurrency's threads), the chunks' sums added in order:
    the same result on any number of threads."""
    chunks = (len(cell) + CHUNK - 1) // CHUNK
    partial = np.zeros((chunks, B.shape[0], 3))
    concurrency.split(
        lambda c0, c1: _gather_chunks(c0, c1, cell, frac, jac, label, B, which, partial), chunks, MIN_CHUNKS
    )
    return _in_order(partial)


@numba.njit(cache=True)
def _in_order(partial):
    """partial[0] + partial[1] + ... in that order."""
    total = np.zeros(partial.shape[1:])
    for c in range(partial.shape[0]):
        total += partial[c]
    return total


@numba.njit(cache=True, nogil=True)
def _gather_chunks(c0, c1, cell, frac, jac, label, B, which, partial):
    """gather's sums of chunks c0..c1-1 into partial[c0:c1]."""
    n = len(cell)
    width = B.shape[2]
    first = 1 if which & FULL else 0
    for c in range(c0, c1):
        for k in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            cl = cell[k]
            if cl < 0:
                continue
            i, j = cl // width, cl % width
            a, b = frac[0, k], frac[1, k]
            for pick in range(2):
                if pick == 0:
                    if not which & FULL:
                        continue
                    m = 0
                else:
                    if not which & QUADRANTS or label[k] < 0:
                        continue
                    m = first + label[k]
                Bm = B[m]
                du = (1 - b) * (Bm[i, j + 1] - Bm[i, j]) + b * (Bm[i + 1, j + 1] - Bm[i + 1, j])
                dv = (1 - a) * (Bm[i + 1, j] - Bm[i, j]) + a * (Bm[i + 1, j + 1] - Bm[i, j + 1])
                for d in range(3):
                    partial[c, m, d] += du * jac[d, k] + dv * jac[3 + d, k]


def blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian of sigma_px [px] with a zero border (a symmetric operator: its own transpose)."""
    if sigma_px <= 0:
        return image
    k = 2 * _radius(sigma_px) + 1
    return cv2.GaussianBlur(image, (k, k), sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_CONSTANT)


def _radius(sigma_px: float) -> int:
    """The half-width [px] of blur's kernel (0: no smoothing)."""
    return int(np.ceil(3.0 * sigma_px)) if sigma_px > 0 else 0


def quadrant_labels(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Each bearing's image quadrant about the optical axis (0: x > 0, y > 0; 1: x > 0, y < 0;
    2: x < 0, y > 0; 3: x < 0, y < 0), -1 on an axis."""
    label = (x < 0).astype(np.int8) * 2 + (y < 0).astype(np.int8)
    label[(x == 0) | (y == 0)] = -1
    return label


class Contrast:
    """The variance of the smoothed IWE of one window of events, and its gradient, per omega;
    and the same of each image quadrant's events (`quadrants`).

    Each evaluation warps every event once (warp_events), votes them in event order (vote),
    smooths and, for the gradient, gathers every event's share (gather); the warp and the
    gather split fixed chunks of events across eas_vo.concurrency's threads: the same results
    on any number of threads.

    Args:
        xy: (N, 2) undistorted normalised coordinates of the events.
        dt: (N,) event time minus the window's reference time [s].
        grid: the IWE (WarpGrid).
        sigma_px: the Gaussian's sigma [px of the grid].
    """

    def __init__(self, xy: np.ndarray, dt: np.ndarray, grid: WarpGrid, sigma_px: float):
        self.x = np.ascontiguousarray(xy[:, 0], dtype=np.float64)
        self.y = np.ascontiguousarray(xy[:, 1], dtype=np.float64)
        self.dt = np.ascontiguousarray(dt, dtype=np.float64)
        self.grid, self.sigma_px = grid, sigma_px
        n = len(self.x)
        self.label = quadrant_labels(self.x, self.y)
        self._index = np.maximum(self.label, 0).astype(np.intp)
        self._cell = np.empty(n, np.int64)
        self._uvz = np.empty((6, n))
        self._frac = np.empty((2, n))
        self._jac = np.empty((6, n))
        self._images = {}
        self.evaluations = 0
        self.landed = 0

    def _pass(self, omegas: np.ndarray, which: int, want_gradient: bool):
        """(values (M,), gradients (M, 3) or None) of the images `which` names, each event
        warped by omegas[0] or (several) its quadrant's omegas[label]."""
        g = self.grid
        M = (1 if which & FULL else 0) + (4 if which & QUADRANTS else 0)
        if M not in self._images:
            self._images[M] = np.empty((M, g.height, g.width))
        images = self._images[M]
        omegas = np.ascontiguousarray(omegas, dtype=np.float64).reshape(-1, 3)
        warp_events(
            self.x,
            self.y,
            self.dt,
            self.label,
            self._index,
            omegas,
            g.fx,
            g.fy,
            g.cx,
            g.cy,
            g.width,
            g.height,
            self._uvz,
            self._cell,
            self._frac,
            self._jac,
        )
        self.landed, box = vote(self._cell, self._frac, self.label, images, which)
        values = np.zeros(M)
        B = np.empty_like(images) if want_gradient else None
        n_px = g.height * g.width
        r = 2 * _radius(self.sigma_px)
        for m in range(M):
            # the smoothed image is zero beyond the radius of the votes' box: smoothed there only
            # (by twice the radius, so the second smoothing is exact over the box, where gather reads)
            i0, i1, j0, j1 = box[m]
            if i0 > i1:
                if want_gradient:
                    B[m] = 0.0
                continue
            rows = slice(max(0, i0 - r), min(g.height, i1 + 1 + r))
            cols = slice(max(0, j0 - r), min(g.width, j1 + 1 + r))
            image = blur(images[m, rows, cols], self.sigma_px)
            mean = image.sum() / n_px
            centred = image - mean
            values[m] = (np.sum(centred * centred) + (n_px - centred.size) * mean * mean) / n_px
            if want_gradient:
                B[m, rows, cols] = blur(centred, self.sigma_px)
        if not want_gradient:
            return values, None
        return values, 2.0 * gather(self._cell, self._frac, self._jac, self.label, B, which) / n_px

    def image(self, omega) -> np.ndarray:
        """The smoothed IWE at omega [rad/s] (height, width)."""
        g = self.grid
        omegas = np.asarray(omega, np.float64).reshape(1, 3)
        warp_events(
            self.x,
            self.y,
            self.dt,
            self.label,
            self._index,
            omegas,
            g.fx,
            g.fy,
            g.cx,
            g.cy,
            g.width,
            g.height,
            self._uvz,
            self._cell,
            self._frac,
            self._jac,
        )
        H = np.empty((1, g.height, g.width))
        self.landed = vote(self._cell, self._frac, self.label, H, FULL)[0]
        return blur(H[0], self.sigma_px)

    def value(self, omega) -> float:
        """Var(IWE) at omega [rad/s] [votes^2 per px]."""
        self.evaluations += 1
        return float(self._pass(omega, FULL, False)[0][0])

    def value_and_gradient(self, omega) -> tuple[float, np.ndarray]:
        """Var(IWE) and its gradient [votes^2 per px per rad/s] at omega [rad/s]."""
        self.evaluations += 1
        values, grads = self._pass(omega, FULL, True)
        return float(values[0]), grads[0]

    def with_quadrants(self, omega) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Var(IWE) and its gradient at omega [rad/s], and the same of each quadrant's events
        alone (quadrant_labels), in one pass: (value, gradient (3,), values (4,), gradients (4, 3))."""
        self.evaluations += 1
        values, grads = self._pass(omega, FULL | QUADRANTS, True)
        return float(values[0]), grads[0], values[1:], grads[1:]

    def quadrants(self, omegas) -> tuple[np.ndarray, np.ndarray]:
        """Each quadrant's Var(IWE) and gradient, its events warped by its own omegas[q] [rad/s]
        (4, 3), in one pass: (values (4,), gradients (4, 3))."""
        self.evaluations += 1
        return self._pass(np.asarray(omegas, np.float64).reshape(4, 3), QUADRANTS, True)


def variance_numpy(xy: np.ndarray, dt: np.ndarray, omega, grid: WarpGrid, sigma_px: float) -> float:
    """The same objective as Contrast.value in plain numpy (scipy's rotation, np.add.at): the
    reference the compiled kernel is checked and timed against."""
    from scipy.spatial.transform import Rotation

    b = np.column_stack([xy, np.ones(len(xy))])
    q = np.einsum("nij,nj->ni", Rotation.from_rotvec(dt[:, None] * np.asarray(omega)[None]).as_matrix(), b)
    front = q[:, 2] > 1e-6
    u = grid.fx * q[front, 0] / q[front, 2] + grid.cx
    v = grid.fy * q[front, 1] / q[front, 2] + grid.cy
    inside = (u >= 0) & (u < grid.width - 1) & (v >= 0) & (v < grid.height - 1)
    u, v = u[inside], v[inside]
    j, i = u.astype(int), v.astype(int)
    a, c = u - j, v - i
    H = np.zeros((grid.height, grid.width))
    for di, dj, wgt in ((0, 0, (1 - a) * (1 - c)), (0, 1, a * (1 - c)), (1, 0, (1 - a) * c), (1, 1, a * c)):
        np.add.at(H, (i + di, j + dj), wgt)
    return float(np.var(blur(H, sigma_px)))
