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
        # dq/dphi = -[q]x J_l(phi), J_l = I + a [p]x + c [p]x^2 = (1 - c t2) I + a [p]x + c p p^T:
        # its column m is l x q, l = J_l e_m = (1 - c t2) e_m + a (p x e_m) + c p_m p
        d = 1.0 - c_ * t2
        for m in range(3):
            e0 = 1.0 if m == 0 else 0.0
            e1 = 1.0 if m == 1 else 0.0
            e2 = 1.0 if m == 2 else 0.0
            pm = p0 * e0 + p1 * e1 + p2 * e2
            # l = J_l e_m
            l0 = d * e0 + a_ * (p1 * e2 - p2 * e1) + c_ * pm * p0
            l1 = d * e1 + a_ * (p2 * e0 - p0 * e2) + c_ * pm * p1
            l2 = d * e2 + a_ * (p0 * e1 - p1 * e0) + c_ * pm * p2
            # dq = l x q
            d0 = l1 * q2 - l2 * q1
            d1 = l2 * q0 - l0 * q2
            d2 = l0 * q1 - l1 * q0
            jac[0, m] = dt * fx * iz * (d0 - q0 * iz * d2)
            jac[1, m] = dt * fy * iz * (d1 - q1 * iz * d2)
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


def blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian of sigma_px [px] with a zero border (a symmetric operator: its own transpose)."""
    if sigma_px <= 0:
        return image
    k = 2 * int(np.ceil(3.0 * sigma_px)) + 1
    return cv2.GaussianBlur(image, (k, k), sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_CONSTANT)


class Contrast:
    """The variance of the smoothed IWE of one window of events, and its gradient, per omega.

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
        self._H = np.zeros((grid.height, grid.width))
        self.evaluations = 0
        self.landed = 0

    def image(self, omega) -> np.ndarray:
        """The smoothed IWE at omega [rad/s] (height, width)."""
        g = self.grid
        self.landed = accumulate(self.x, self.y, self.dt, np.asarray(omega, np.float64), g.fx, g.fy, g.cx, g.cy, self._H)
        return blur(self._H, self.sigma_px)

    def value(self, omega) -> float:
        """Var(IWE) at omega [rad/s] [votes^2 per px]."""
        self.evaluations += 1
        return float(np.var(self.image(omega)))

    def value_and_gradient(self, omega) -> tuple[float, np.ndarray]:
        """Var(IWE) and its gradient [votes^2 per px per rad/s] at omega [rad/s]."""
        self.evaluations += 1
        omega = np.asarray(omega, np.float64)
        image = self.image(omega)
        mean = image.mean()
        B = blur(image - mean, self.sigma_px)
        g = self.grid
        grad = gather_gradient(self.x, self.y, self.dt, omega, g.fx, g.fy, g.cx, g.cy, B)
        return float(np.mean((image - mean) ** 2)), 2.0 * grad / image.size


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
