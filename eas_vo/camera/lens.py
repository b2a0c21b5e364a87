"""The lens models' projection, compiled: rays or normalised image coordinates to distorted
pixels. CameraModel.project is its interface (docs/camera_models.md has the equations); it is
compiled because a warp through the lens projects every pixel of an image for every frame."""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, nogil=True, error_model="numpy")  # (a ray at z = 0: inf or nan, as numpy gives)
def project_points(points, K, dist, equidistant, out):
    """Rays (N, 3) in the camera frame, or normalised image coordinates (N, 2) (z = 1), into
    `out` (N, 2): distorted pixel coordinates [px], through the `equidistant` (Kannala-Brandt:
    k1..k4 of `dist` distort the angle to the optical axis) or the radial-tangential lens
    (k1 k2 p1 p2 k3: x / z and y / z distorted). K: 3x3 intrinsics [px]."""
    three = points.shape[1] == 3
    for n in range(points.shape[0]):
        x, y = points[n, 0], points[n, 1]
        z = points[n, 2] if three else 1.0
        if equidistant:
            k1, k2, k3, k4 = dist[0], dist[1], dist[2], dist[3]
            r = math.hypot(x, y)
            theta = math.atan2(r, z)
            t2 = theta * theta
            theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
            # theta_d / r -> 1 / z on the optical axis
            scale = theta_d / r if r > 0 else 1.0 / (z if z > 0 else 1.0)
            xd, yd = x * scale, y * scale
        else:
            k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
            x, y = x / z, y / z
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        out[n, 0] = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
        out[n, 1] = K[1, 1] * yd + K[1, 2]


def first_fold(coefficients, limit: float) -> float:
    """The smallest x in (0, limit] at which the radial projection f(x) = x (1 + c1 x^2 + c2 x^4
    + ...) stops growing (f'(x) = 0, f'(0) = 1), `limit` if it grows all the way there.
    `coefficients` c1, c2, ...: radtan's k1 k2 k3 with x = tan(theta), the normalised radius;
    equidistant's k1..k4 with x = theta [rad], the angle to the optical axis."""
    import numpy as np

    # f'(x) = 1 + 3 c1 s + 5 c2 s^2 + ... in s = x^2, highest power first for np.roots
    derivative = [(2 * n + 1) * float(c) for n, c in enumerate([1.0, *coefficients])][::-1]
    roots = np.roots(np.trim_zeros(derivative, "f")) if any(derivative[:-1]) else np.empty(0)
    s = [r.real for r in roots if abs(r.imag) <= 1e-12 * max(1.0, abs(r.real)) and r.real > 0]
    return min([math.sqrt(v) for v in s if math.sqrt(v) < limit], default=limit)
