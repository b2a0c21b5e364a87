"""The contrast-maximisation kernels: the compiled warp against scipy's rotations, the compiled
objective against the plain numpy one, and the analytic gradient against finite differences."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eas_vo import concurrency
from eas_vo.trackers.contrast import (
    CHUNK,
    MIN_CHUNKS,
    Contrast,
    WarpGrid,
    accumulate,
    blur,
    gather_gradient,
    quadrant_labels,
    variance_numpy,
)


def window(seed: int, n: int, width: int, height: int, focal: float, span_s: float = 0.02):
    """n random bearings inside a width x height pinhole view and their times about t_ref [s]."""
    rng = np.random.default_rng(seed)
    grid = WarpGrid(width, height, focal, focal, (width - 1) / 2, (height - 1) / 2)
    u, v = rng.uniform(0, width - 1, n), rng.uniform(0, height - 1, n)
    xy = np.column_stack([(u - grid.cx) / grid.fx, (v - grid.cy) / grid.fy])
    # clustered on a few lines, so the image has structure the gradient can see
    xy[: n // 2, 1] = np.round(xy[: n // 2, 1] * 8) / 8
    return xy, rng.uniform(-span_s / 2, span_s / 2, n), grid


@pytest.mark.parametrize("omega_deg", [(0.0, 0.0, 0.0), (30.0, -200.0, 10.0), (700.0, 500.0, -900.0)])
def test_one_event_lands_where_scipy_rotates_its_bearing(omega_deg):
    grid = WarpGrid(240, 180, 200.0, 200.0, 121.5, 89.0)
    omega = np.radians(omega_deg)
    b = np.array([0.1, -0.05, 1.0])
    dt = 0.013
    q = Rotation.from_rotvec(omega * dt).apply(b)
    expected = grid.fx * q[0] / q[2] + grid.cx, grid.fy * q[1] / q[2] + grid.cy
    H = np.zeros((grid.height, grid.width))
    assert (
        accumulate(np.array([b[0]]), np.array([b[1]]), np.array([dt]), omega, grid.fx, grid.fy, grid.cx, grid.cy, H)
        == 1
    )
    rows, cols = np.nonzero(H)
    centroid = (np.sum(cols * H[rows, cols]), np.sum(rows * H[rows, cols]))
    assert H.sum() == pytest.approx(1.0)
    assert centroid == pytest.approx(expected, abs=1e-7)  # the series below 0.3 rad: 2e-10 of 200 px


@pytest.mark.parametrize("size", [(240, 180, 200.0), (346, 260, 226.0), (640, 480, 520.0)])
@pytest.mark.parametrize("sigma_px", [0.0, 1.0, 2.5])
def test_the_compiled_objective_equals_the_numpy_one(size, sigma_px):
    xy, dt, grid = window(1, 5000, *size)
    contrast = Contrast(xy, dt, grid, sigma_px)
    for omega in (np.zeros(3), np.radians([100.0, -300.0, 50.0]), np.radians([-900.0, 400.0, 800.0])):
        assert contrast.value(omega) == pytest.approx(variance_numpy(xy, dt, omega, grid, sigma_px), rel=1e-9)


@pytest.mark.parametrize("size", [(240, 180, 200.0), (346, 260, 226.0)])
@pytest.mark.parametrize("seed", range(3))
def test_the_gradient_is_the_derivative_of_the_objective(size, seed):
    xy, dt, grid = window(seed, 20000, *size)
    contrast = Contrast(xy, dt, grid, 1.0)
    omega = np.radians(np.random.default_rng(10 + seed).uniform(-600, 600, 3))
    value, grad = contrast.value_and_gradient(omega)
    assert value == pytest.approx(contrast.value(omega), rel=1e-12)
    h = 1e-5  # rad/s: ~2e-6 px, so few events cross a bilinear cell edge (where the derivative jumps)
    numeric = [(contrast.value(omega + h * e) - contrast.value(omega - h * e)) / (2 * h) for e in np.eye(3)]
    np.testing.assert_allclose(grad, numeric, rtol=2e-3, atol=1e-3 * np.abs(numeric).max())


def serial_value_and_gradient(xy, dt, omega, grid, sigma_px):
    """The objective and its gradient by the serial reference kernels (accumulate, gather_gradient)."""
    x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
    H = np.zeros((grid.height, grid.width))
    accumulate(x, y, dt, omega, grid.fx, grid.fy, grid.cx, grid.cy, H)
    image = blur(H, sigma_px)
    centred = image - image.mean()
    B = blur(centred, sigma_px)
    grad = gather_gradient(x, y, dt, omega, grid.fx, grid.fy, grid.cx, grid.cy, B)
    return float(np.mean(centred**2)), 2.0 * grad / image.size


@pytest.mark.parametrize("size", [(240, 180, 200.0), (346, 260, 226.0)])
@pytest.mark.parametrize("sigma_px", [0.0, 1.0, 2.5])
def test_the_parallel_kernels_equal_the_serial_ones_on_any_number_of_threads(size, sigma_px):
    xy, dt, grid = window(4, 3 * MIN_CHUNKS * CHUNK + 123, *size)  # 3 threads' parts, the last chunk partial
    omega = np.radians([150.0, -420.0, 260.0])
    expected = serial_value_and_gradient(xy, dt, omega, grid, sigma_px)
    results = []
    before = concurrency.threads()
    for threads in (1, 2, 3):  # 3: parts of unequal length
        concurrency.set_threads(threads)
        try:
            results.append(Contrast(xy, dt, grid, sigma_px).value_and_gradient(omega))
        finally:
            concurrency.set_threads(before)
    for value, grad in results:
        assert value == pytest.approx(expected[0], rel=1e-12)
        np.testing.assert_allclose(grad, expected[1], rtol=1e-10, atol=1e-14 * np.abs(expected[1]).max())
    assert all(v == results[0][0] and np.array_equal(g, results[0][1]) for v, g in results)  # bit for bit


def test_one_pass_gives_the_window_and_each_quadrant_as_if_alone():
    xy, dt, grid = window(5, 20000, 240, 180, 200.0)
    xy[:40, 0] = 0.0  # on an axis: in the window, in no quadrant
    contrast = Contrast(xy, dt, grid, 1.0)
    label = quadrant_labels(contrast.x, contrast.y)
    assert np.all(label[:40] == -1) and {0, 1, 2, 3} <= set(np.unique(label[40:]).tolist())
    omega = np.radians([40.0, -250.0, 120.0])
    value, grad, values, grads = contrast.with_quadrants(omega)
    whole_value, whole_grad = contrast.value_and_gradient(omega)
    assert value == pytest.approx(whole_value, rel=1e-12)
    np.testing.assert_allclose(grad, whole_grad, rtol=1e-10, atol=1e-14)
    omegas = omega + np.radians([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0], [0.0, -60.0, 10.0], [5.0, 5.0, -90.0]])
    alone_values, alone_grads = contrast.quadrants(omegas)
    for q in range(4):
        part = Contrast(xy[label == q], dt[label == q], grid, 1.0)
        v, g = part.value_and_gradient(omega)
        assert values[q] == pytest.approx(v, rel=1e-12)
        np.testing.assert_allclose(grads[q], g, rtol=1e-10, atol=1e-14)
        v, g = part.value_and_gradient(omegas[q])
        assert alone_values[q] == pytest.approx(v, rel=1e-12)
        np.testing.assert_allclose(alone_grads[q], g, rtol=1e-10, atol=1e-14)
