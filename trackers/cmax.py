"""`cmax`: the camera's angular velocity from events alone, by contrast maximisation (Gallego
and Scaramuzza, RA-L 2017), integrated into the rotation between consecutive samples.

Between two samples the events are cut into windows (by count or by time); in each, the
angular velocity maximising the variance of the image of warped events (trackers.contrast)
is found by Newton steps in the metric of the objective's curvature (_newton) from the gyro's
mean rate over the window when the dataset has one, the previous window's estimate, or
(nothing to start from, or no contrast found) a coarse search.
The rotation between the samples multiplies each window's Exp(omega dt) over the part of the
interval the window stands for; its covariance comes from the objective's curvature (each
window's Hessian, _rotation_covariance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eas_vo.geometry.rotations import matrix_to_rotvec, rotvec_to_matrix
from eas_vo.plugins import Tracker
from eas_vo.trackers.contrast import Contrast, WarpGrid
from eas_vo.types import FrameRecord, RelativeRotation, Sample
from eas_vo.validation import check_choice, check_range

INITS = ("auto", "previous", "search")

#: The uncertainty of a window's omega is SIGMA_SCALE times the objective's curvature radius:
#: its covariance SIGMA_SCALE^2 H^-1 [px^2 of displacement over half the window], H the Hessian
#: of the cost (Window.covariance), whose RMS over the axes, sqrt(trace / 3), is the scalar
#: Window.sigma_rad_s. The scale was fitted on that scalar, so that the per-axis errors of the
#: rotations between frames have unit RMS on the development sequences (docs/cmax.md, "How it
#: works", step 4, has their figures); the full covariance keeps its trace and gives each axis
#: its own share of it.
SIGMA_SCALE = 0.034
#: The 1-sigma [rad] of a rotation whose objective has no curvature (a flat optimum), and the
#: most any axis of a rotation's covariance states: a backend weighing it by its covariance all
#: but ignores it.
FLAT_SIGMA_RAD = 1.0
#: The pixel count (the DAVIS240's 240 x 180) at which the focus and gain thresholds of
#: CmaxConfig are stated. On events without motion the focus and gain fluctuate from warp to
#: warp by an amount that does not depend on the number of events but on the number of
#: independent blobs of the smoothing kernel in the image: relatively, about
#: 2 sigma_px sqrt(pi / pixels) for the contrast (the pairs of events within the kernel's reach
#: of each other); the focus of noise is 1.000 +- 0.002 at 240 x 180 and +- 0.004 at 120 x 90.
#: A threshold's excess over 1 is scaled by sqrt(REFERENCE_PIXELS / pixels) (CmaxTracker.thresholds),
#: so that it stands as far above the noise on every sensor.
REFERENCE_PIXELS = 240 * 180
#: The focus of a window compares its contrast with that of warps displacing the events this
#: far [px over half the window]: about the width of the peak a sharp edge makes (sigma_px 1).
FOCUS_STEP_PX = 1.0
#: The coarse search's image (CmaxTracker._search) is built from about this many of a window's
#: events: at its resolution (a cell of about half the grid's spacing, 11 px of the DAVIS240 in
#: a 40,000-event window of hand-held motion) some ten events fall in each cell.
SEARCH_EVENTS = 4000
#: A hot pixel has fired this many times the mean pixel's count (CmaxTracker._without_hot_pixels):
#: more than an edge-rich pixel in fast motion fires within a window, less than a hot pixel's
#: rate over a signal pixel's (docs/cmax.md, "Status: ok, weak, lost", has the rates measured).
HOT_PIXEL_FACTOR = 20.0
#: The solver (_newton) works on the contrast over that at no motion, in px of displacement over
#: half a window, with Newton steps in the metric of the objective's curvature (central
#: differences of the analytic gradient 1 px apart: the scale on which the bilinear votes'
#: kinks are smoothed over), which the window before measured at its optimum. It stops once a
#: step would be under NEWTON_TOL_PX, well below how precisely the peak's position is known; a
#: line-search solver (scipy's L-BFGS-B) fails on those kinks (docs/cmax.md, "How it works",
#: step 3, has the curvatures and evaluation counts measured).
NEWTON_TOL_PX = 0.01
#: A step is at most this long [px] (the curvature's 1 px scale; halved after a step that lowered
#: the contrast, back to this after one that raised it); the solver evaluates at most NEWTON_EVALS points.
NEWTON_RADIUS_PX = 2.0
NEWTON_EVALS = 20
#: The quadrants' optima need less: a fraction of max_residual_px, at most QUADRANT_EVALS passes.
QUADRANT_TOL_PX = 0.05
QUADRANT_EVALS = 2
HOT_PIXEL_MIN_EVENTS = 8
#: An interval whose longest stretch without any event (its ends included) is over this share of
#: it is `weak`: the rotation there is the rate measured elsewhere, extrapolated over more of
#: the interval than it was measured on (events missing: a dropped transfer, a bias reset).
MAX_UNCOVERED = 0.5


@dataclass(frozen=True)
class CmaxConfig:
    """Attributes:
    window_events: events per window when window_s is 0: the interval between two samples is
        cut into round(N / window_events) windows (at least one) of its own events only (an
        interval with fewer is one window: a window padded from before it would measure the
        interval before).
    window_s: window length [s] instead (0: by events): round(interval / window_s) windows,
        one holding over 2 * window_events events cut further by count.
    sigma_px: the Gaussian smoothing the image of warped events [px of the sensor].
    min_events: a window with fewer events (hot pixels left out) is not measured (the frame is `lost`).
    lost_focus, lost_gain: a focus (the optimum's contrast over that of warps FOCUS_STEP_PX
        away) at or below lost_focus with a contrast gain (over no motion) at or below
        lost_gain measures nothing: nothing was brought into focus and no blur removed.
        Neither alone is a test: slow motion, well measured, has gains near 1, and fast
        motion in dim light a focus near 1 (the events' latency spread blurs its sharpest
        image beyond a pixel); docs/cmax.md, "Status: ok, weak, lost", has the figures.
    weak_focus: a focus below this makes the frame `weak`.
        The three are stated for the DAVIS240's 240 x 180 pixels: on another sensor their
        excess over 1 is scaled by sqrt(REFERENCE_PIXELS / pixels), as the noise of the focus
        and the gain is (CmaxTracker.thresholds).
    max_residual_px: the frame is `weak` when the image quadrants' own optima lie further
        apart than this [px of displacement over half a window]: one rotation does not
        explain the events (translation before a near scene, independent motion).
    init: where the solver starts: `auto` (the gyro when the dataset has one, else the previous
        window; a coarse search when neither; no motion too when the optimum found is no
        better than no motion), `previous` (never the gyro), `search` (the coarse search
        and no motion, always).
    max_rate_deg_s: the coarse search covers |omega| per axis up to this [deg/s].
    """

    window_events: int = 40000
    window_s: float = 0.0
    sigma_px: float = 1.0
    min_events: int = 1000
    lost_focus: float = 1.005
    lost_gain: float = 1.15
    weak_focus: float = 1.01
    max_residual_px: float = 1.5
    init: str = "auto"
    max_rate_deg_s: float = 1500.0

    def validate(self) -> None:
        check_range(self, "window_events", 100, 10_000_000)
        check_range(self, "window_s", 0.0, 10.0)
        check_range(self, "sigma_px", 0.0, 20.0)
        check_range(self, "min_events", 10, 10_000_000)
        check_range(self, "lost_focus", 1.0, 100.0)
        check_range(self, "lost_gain", 1.0, 100.0)
        check_range(self, "weak_focus", self.lost_focus, 100.0)
        check_range(self, "max_residual_px", 0.0, 1e6, lo_open=True)
        check_choice(self, "init", INITS)
        check_range(self, "max_rate_deg_s", 1.0, 100_000.0)


@dataclass(frozen=True)
class Window:
    """One window's estimate: omega [rad/s] (camera frame), its RMS 1-sigma over the axes [rad/s]
    (from the curvature of the objective: sqrt(trace(covariance) / 3)), the contrast gain (over no motion), the focus (over warps
    FOCUS_STEP_PX away), the events read, the span [s] of the
    interval it stands for, how many times the objective was evaluated, how far apart the
    image quadrants' own optima lie (CmaxTracker._quadrant_residual_px) [px], the angular
    velocity [rad/s] that displaces its events 1 px over half the window (rad_s_per_px), and no
    motion's own focus where the gain is below the focus (0 where it is not: the optimum stands
    clear of no motion), whether the solver started uninformed: from the coarse search (no gyro
    and no previous window: a standing start) or from a previous window's omega that was itself
    found uninformed and little in focus (a noise peak the search may have settled on is no
    better a start), and the covariance of omega [(rad/s)^2] (3, 3): SIGMA_SCALE^2 times the
    inverse of the objective's Hessian, in rad/s (None where the optimum is not a minimum of the
    cost: no curvature along some axis)."""

    omega: np.ndarray
    sigma_rad_s: float
    gain: float
    focus: float
    events: int
    t0: float
    t1: float
    evaluations: int
    residual_px: float
    rad_s_per_px: float = 0.0
    still_focus: float = 0.0
    uninformed: bool = False
    covariance: np.ndarray | None = None


class CmaxTracker(Tracker):
    """Angular velocity by contrast maximisation per window of events; R_{k-1}_{k} integrated from it."""

    name = "cmax"
    description = "events alone: angular velocity by contrast maximisation (variance of warped events), integrated"
    Config = CmaxConfig
    needs_events = True
    reads_images = False

    @property
    def uses_imu(self) -> bool:
        return self.config.init == "auto"

    @property
    def thresholds(self) -> tuple[float, float, float]:
        """(lost_focus, lost_gain, weak_focus) for this camera: the config's, stated for
        REFERENCE_PIXELS, with their excess over 1 scaled by sqrt(REFERENCE_PIXELS / pixels)."""
        c, cam = self.config, self.camera
        factor = float(np.sqrt(REFERENCE_PIXELS / (cam.width * cam.height)))
        values = (c.lost_focus, c.lost_gain, c.weak_focus)
        return values if factor == 1.0 else tuple(1.0 + (v - 1.0) * factor for v in values)

    def reset(self) -> None:
        cam = self.camera
        self._bearing = cam.pixel_rays[:, :2].reshape(cam.height, cam.width, 2)
        self._grid = WarpGrid.of(cam.K, cam.width, cam.height)
        self._omega: np.ndarray | None = None  # the last window's, None when lost
        self._metric: np.ndarray | None = None  # the curvature at the last window's optimum [per px^2]
        self._uninformed = False  # whether the last window's omega is an uninformed start (Window.uninformed)
        self._lost_focus, self._lost_gain, self._weak_focus = self.thresholds
        self._counts = np.zeros(cam.width * cam.height, np.int64)  # events per pixel so far (hot pixels)
        self._prev_t = -np.inf
        self._k = -1
        self.windows: list[Window] = []  # the last interval's windows (memory bounded by the config)

    def process(self, image, t: float, *, sample: Sample | None = None) -> tuple[FrameRecord, list[RelativeRotation]]:
        self._k += 1
        k = self._k
        if k == 0:
            self._prev_t = t
            return FrameRecord(k, t, 0, 0, "first", False), []
        if t <= self._prev_t:
            return FrameRecord(k, t, 0, 0, "same_time", False), []
        t_prev, self._prev_t = self._prev_t, t
        events = sample.events_since_previous  # those of [t_prev, t): a window never reaches outside
        cut = self._windows(events, t_prev, t)
        if cut is None:
            self._omega = None
            return FrameRecord(
                k, t, 0, 0, "lost", False, reason=f"too few events ({len(events)})", events=len(events)
            ), []
        windows = [self.measure(chunk, lo, hi) for chunk, lo, hi in cut]
        self.windows = windows
        n = sum(w.events for w in windows)
        gain = min(w.gain for w in windows)
        focus = min(w.focus for w in windows)
        if any(w.events < self.config.min_events for w in windows):
            self._omega = None
            return FrameRecord(k, t, 0, 0, "lost", False, reason=f"too few events ({n})", events=n), []
        if focus <= self._lost_focus and gain <= self._lost_gain:
            self._omega = None
            return FrameRecord(
                k, t, 0, 0, "lost", False, reason=f"nothing in focus ({focus:.3f})", events=n, contrast_gain=gain
            ), []
        R, covariance = _integrated(windows)
        residual = max(w.residual_px for w in windows)
        uncovered = _longest_gap(events["t"], t_prev, t) / (t - t_prev)
        uninformed = any(w.uninformed for w in windows)
        status, reason, floor = "ok", "", 0.0  # floor: the least sigma [rad] any axis of the covariance states
        if uncovered > MAX_UNCOVERED:
            status, reason = "weak", f"events miss part of the interval ({100 * uncovered:.0f} % without any)"
        elif focus < self._weak_focus:
            status, reason = "weak", f"little in focus ({focus:.3f})"
        elif any(w.still_focus >= self._weak_focus for w in windows):
            # two peaks, the optimum and no motion, no farther apart in contrast than the optimum's own
            # width: a motion under about a pixel, not told from none (a noise peak a few px away passes
            # the focus test): the rotation is known to within itself and the peak's width
            still = max(w.still_focus for w in windows)
            status, reason = "weak", f"as sharp at no motion ({still:.3f})"
            floor = _within_itself(R, windows)
        elif residual > self.config.max_residual_px:
            # the rotation is known no better than the quadrants agree: every axis's sigma is at least their spread
            status, reason = "weak", f"quadrants disagree ({residual:.2f} px)"
            floor = _angle(windows, lambda w: w.residual_px)
        elif covariance is None:
            status, reason = "weak", "flat objective"
        if status == "weak" and uninformed:
            # from an uninformed start (docs/cmax.md) the optimum may be a far noise peak, which a weak
            # window does not rule out: the rotation is known to within itself and the peak's width
            floor = max(floor, _within_itself(R, windows))
        # the edge's inliers: the events an ok estimate rests on, none for a weak one (what makes an
        # edge confident for the gyro's check, imu.verdict.CONFIDENT_INLIERS: a weak window is not)
        record = FrameRecord(
            k, t, 0, n, status, False, residual_px=residual, reason=reason, events=n, contrast_gain=gain
        )
        confident = n if status == "ok" else 0
        return record, [RelativeRotation(k - 1, k, R, inliers=confident, covariance=_bounded(covariance, floor))]

    def _windows(self, events: np.ndarray, t_prev: float, t: float):
        """(events, t0, t1) per window: its events, all within [t_prev, t), and the part [t0, t1]
        of [t_prev, t] it stands for; None when some window would hold fewer than min_events.
        An interval of any length or density makes at most len(events) / min_events windows,
        none of over 2 * window_events events (the memory a window's measurement takes, about
        110 bytes an event, is bounded by the configuration)."""
        c = self.config
        if c.window_s <= 0:
            return _by_count(events, t_prev, t, c.window_events, c.min_events)
        n = max(1, round((t - t_prev) / c.window_s))
        if n * c.min_events > len(events):  # some window would hold fewer than min_events
            return None
        cuts = np.linspace(t_prev, t, n + 1)
        bounds = np.searchsorted(events["t"], cuts)
        windows = []
        for i in range(n):
            chunk = events[bounds[i] : bounds[i + 1]]
            if len(chunk) > 2 * c.window_events:
                windows += _by_count(chunk, cuts[i], cuts[i + 1], c.window_events, c.min_events)
            else:
                windows.append((chunk, cuts[i], cuts[i + 1]))
        return windows

    def measure(self, events: np.ndarray, t0: float, t1: float) -> Window:
        """The angular velocity of one window of events standing for [t0, t1] [s]."""
        c = self.config
        events = self._without_hot_pixels(events)
        n = len(events)
        if n < c.min_events:
            return Window(np.zeros(3), np.inf, 1.0, 1.0, n, t0, t1, 0, 0.0)
        times = events["t"]
        t_ref = 0.5 * (float(times[0]) + float(times[-1]))
        xy = self._bearing[events["y"].astype(np.intp), events["x"].astype(np.intp)]
        contrast = Contrast(xy, times - t_ref, self._grid, c.sigma_px)
        # optimise in px: omega * (half the window) * focal length is the displacement it causes
        scale = max(0.5 * (float(times[-1]) - float(times[0])), 1e-6) * self.camera.focal_px
        v0 = contrast.value(np.zeros(3))
        if v0 <= 0:
            return Window(np.zeros(3), np.inf, 1.0, 1.0, n, t0, t1, contrast.evaluations, 0.0)

        def cost(p):
            value, grad = contrast.value_and_gradient(p / scale)
            return -value / v0, -grad / (v0 * scale)

        starts, informed = self._starts(t0, t1)
        searched = not starts or c.init == "search"
        if searched:
            starts += [self._search(contrast, scale), np.zeros(3)]
        best = None
        for start in starts:
            best = _lower(best, _newton(cost, start * scale, self._metric))
        if -best[1] <= 1.0 and c.init != "search":  # no better than no motion (slow motion, or a bad start)
            best = _lower(best, _newton(cost, np.zeros(3), self._metric))
        p = best[0]
        omega = p / scale
        # the curvature, the focus and the quadrants' gradients and curvatures, from the 7 passes
        # at the optimum and 1 px from it along each axis
        centre = contrast.with_quadrants(omega)
        around = [
            contrast.with_quadrants((p + sign * FOCUS_STEP_PX * e) / scale) for e in np.eye(3) for sign in (1.0, -1.0)
        ]
        H = np.column_stack([around[2 * i][1] - around[2 * i + 1][1] for i in range(3)])
        H /= -2 * FOCUS_STEP_PX * v0 * scale
        H = 0.5 * (H + H.T)
        covariance = _curvature_covariance(H)
        self._metric = H if covariance is not None else None
        focus = float(centre[0] / np.mean([a[0] for a in around]))
        residual = self._quadrant_residual_px(contrast, p, scale, centre, around, H)
        gain = float(-best[1])
        # no motion's own focus, where the optimum stands above it by less than above its neighbours
        still_focus = 0.0
        if gain < focus:
            still_focus = v0 / np.mean(
                [contrast.value(sign * FOCUS_STEP_PX * e / scale) for e in np.eye(3) for sign in (1.0, -1.0)]
            )
        uninformed = searched or not informed
        self._omega, self._uninformed = omega, uninformed and focus < self._weak_focus
        return Window(
            omega,
            np.inf if covariance is None else float(np.sqrt(np.trace(covariance) / 3.0)) / scale,
            gain,
            focus,
            n,
            t0,
            t1,
            contrast.evaluations,
            residual,
            1.0 / scale,
            still_focus,
            uninformed,
            None if covariance is None else covariance / scale**2,
        )

    def _quadrant_residual_px(self, contrast: Contrast, p: np.ndarray, scale: float, centre, around, H) -> float:
        """How far apart the four image quadrants' own optima lie [px of displacement over half
        the window]: each quadrant's events alone, from the window's optimum p [px] (its gradient
        `centre` there and curvature from `around`, Contrast.with_quadrants; H the window's
        curvature), Newton steps of all four at once (Contrast.quadrants); the largest distance
        from p. One rotation moves every
        quadrant alike (a fraction of a pixel apart); translation before a near scene (expansion,
        parallax) does not."""
        counts = np.bincount(contrast.label[contrast.label >= 0], minlength=4)
        v = centre[2]
        use = [q for q in range(4) if counts[q] >= self.config.min_events // 4 and v[q] > 0]
        if not use:
            return 0.0
        h = FOCUS_STEP_PX
        # cost_q(p) = -V_q(p) / V_q(optimum), in px
        grads = {q: -centre[3][q] / (v[q] * scale) for q in use}
        metrics = {
            q: np.column_stack([(around[2 * i][3][q] - around[2 * i + 1][3][q]) for i in range(3)])
            / (-2 * h * v[q] * scale)
            for q in use
        }
        # a direction a quadrant alone hardly constrains (roll, within a quadrant, is nearly a
        # shift) would send its Newton steps far on its texture's noise: its curvature is taken
        # as at least the whole window's flattest
        floor = np.linalg.eigvalsh(_positive_definite(H))[0]
        for q in use:
            lam, V = np.linalg.eigh(0.5 * (metrics[q] + metrics[q].T))
            metrics[q] = (V * np.maximum(lam, floor)) @ V.T
        solvers = {q: _NewtonSteps(p, -1.0, grads[q], metrics[q], QUADRANT_TOL_PX) for q in use}
        for _ in range(QUADRANT_EVALS):
            trial = {q: solvers[q].proposal() for q in use}
            if all(t is None for t in trial.values()):
                break
            omegas = np.tile(p, (4, 1))
            for q, t in trial.items():
                if t is not None:
                    omegas[q] = t
            values, gradients = contrast.quadrants(omegas / scale)
            for q, t in trial.items():
                if t is not None:
                    solvers[q].update(-values[q] / v[q], -gradients[q] / (v[q] * scale))
        return max(float(np.linalg.norm(solvers[q].p - p)) for q in use)

    def _without_hot_pixels(self, events: np.ndarray) -> np.ndarray:
        """`events` less those of hot pixels: pixels that fired HOT_PIXEL_FACTOR times the mean
        pixel's count since the sequence began (and at least HOT_PIXEL_MIN_EVENTS). Their
        events stay where they are under any warp, so they would pass for a focused image of
        no motion (docs/cmax.md, "Status: ok, weak, lost")."""
        pixel = events["y"].astype(np.intp) * self.camera.width + events["x"].astype(np.intp)
        self._counts += np.bincount(pixel, minlength=self._counts.size)
        hot = self._counts > max(HOT_PIXEL_MIN_EVENTS, HOT_PIXEL_FACTOR * self._counts.mean())
        return events[~hot[pixel]]

    def _starts(self, t0: float, t1: float) -> tuple[list[np.ndarray], bool]:
        """Where the solver starts [rad/s]: the gyro's mean rate over [t0, t1], else the previous
        window's; and whether that start is informed (the gyro's, or a previous window's that was
        not itself found uninformed and little in focus)."""
        if self.config.init == "auto" and self.imu is not None and self.imu.covered(t0, t1):
            rates, durations = self.imu.rates_between(t0, t1)
            return [rates.T @ durations / max(durations.sum(), 1e-12)], True
        return ([], False) if self._omega is None else ([self._omega], not self._uninformed)

    def _search(self, contrast: Contrast, scale: float) -> np.ndarray:
        """The best omega [rad/s] of a 7 x 7 x 7 grid up to max_rate_deg_s per axis, the image
        smoothed to half the grid's spacing (so the optimum's basin is not stepped over), from
        about SEARCH_EVENTS of the events, evenly spread. The image is made at the resolution of that smoothing (pixels
        `shrink` times the sensor's, smoothed by the same sigma in sensor pixels): the same
        objective at a fraction of the cost of blurring the sensor-sized image by a wide kernel."""
        steps = np.radians(self.config.max_rate_deg_s) * np.linspace(-1, 1, 7)
        spacing_px = (steps[1] - steps[0]) * scale
        sigma_px = max(contrast.sigma_px, 0.5 * spacing_px)
        shrink = max(1, int(sigma_px / max(contrast.sigma_px, 1.0)))
        g = contrast.grid
        small = WarpGrid(
            -(-g.width // shrink),
            -(-g.height // shrink),
            g.fx / shrink,
            g.fy / shrink,
            (g.cx + 0.5) / shrink - 0.5,
            (g.cy + 0.5) / shrink - 0.5,
        )
        every = max(1, len(contrast.dt) // SEARCH_EVENTS)
        coarse = Contrast(
            np.column_stack([contrast.x, contrast.y])[::every], contrast.dt[::every], small, sigma_px / shrink
        )
        grid = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), -1).reshape(-1, 3)
        values = [coarse.value(w) for w in grid]
        contrast.evaluations += coarse.evaluations
        return grid[int(np.argmax(values))]


class _NewtonSteps:
    """Newton's method on a cost [px] from p (its value f and gradient g there) in the metric of
    the curvature H (its eigenvalues' magnitudes, floored at 1e-3 of the largest, so every step
    goes downhill), updated by BFGS from each accepted step of at least 0.25 px; a step is at most
    `radius` px long, halved after a step that raised the cost. `proposal` is the next point to
    evaluate (None once a step would be under tol_px), `update` takes its cost and gradient."""

    def __init__(self, p, f, g, H, tol_px: float, radius: float = NEWTON_RADIUS_PX):
        self.p, self.f, self.g = np.asarray(p, float), float(f), np.asarray(g, float)
        self.M, self.tol, self.radius = _positive_definite(H), tol_px, radius
        self._step = None

    def proposal(self):
        step = -np.linalg.solve(self.M, self.g)
        length = float(np.linalg.norm(step))
        if not np.isfinite(length):
            return None
        if length > self.radius:
            step *= self.radius / length
            length = self.radius
        if length < self.tol:
            return None
        self._step = step
        return self.p + step

    def update(self, f: float, g: np.ndarray) -> None:
        step, length = self._step, float(np.linalg.norm(self._step))
        if f < self.f:
            y = g - self.g
            sy = float(step @ y)
            if length >= 0.25 and sy > 0:
                Ms = self.M @ step
                self.M = self.M - np.outer(Ms, Ms) / float(step @ Ms) + np.outer(y, y) / sy
            self.p, self.f, self.g = self.p + step, f, g
            self.radius = NEWTON_RADIUS_PX
        else:
            self.radius = 0.5 * length


def _newton(cost, p: np.ndarray, H: np.ndarray | None) -> tuple[np.ndarray, float]:
    """The minimum of `cost` [px] found by _NewtonSteps from p [px], in the metric H (None: the
    curvature at p, by central differences of the gradient 1 px apart); (p, cost)."""
    f, g = cost(p)
    if H is None:
        H = _hessian(cost, p)
    solver = _NewtonSteps(p, f, g, H, NEWTON_TOL_PX)
    for _ in range(NEWTON_EVALS):
        trial = solver.proposal()
        if trial is None:
            break
        solver.update(*cost(trial))
    return solver.p, solver.f


def _by_count(events: np.ndarray, t0: float, t1: float, per_window: int, min_events: int):
    """[t0, t1]'s `events` cut into round(N / per_window) windows (at least one) of about equal
    counts, each standing for [t0, t1] cut halfway between its last event and the next's;
    None under min_events."""
    if len(events) < min_events:
        return None
    n = max(1, round(len(events) / per_window))
    bounds = np.linspace(0, len(events), n + 1).round().astype(int)
    times = events["t"]
    cuts = [t0] + [0.5 * (times[b - 1] + times[b]) for b in bounds[1:-1]] + [t1]
    return [(events[bounds[i] : bounds[i + 1]], cuts[i], cuts[i + 1]) for i in range(n)]


def _angle(windows, px) -> float:
    """The angle [rad] over the windows' intervals, added in quadrature, of displacing each
    window's events px(window) pixels over half the window."""
    return float(np.sqrt(sum((px(w) * w.rad_s_per_px * (w.t1 - w.t0)) ** 2 for w in windows)))


def _longest_gap(times: np.ndarray, t0: float, t1: float) -> float:
    """The longest stretch [s] of [t0, t1] without any of the event `times` (within it, sorted), its ends included."""
    return float(np.max(np.diff(np.concatenate([[t0], times, [t1]]))))


def _lower(best, found):
    """The lower of two (p, cost) (best None: found)."""
    return found if best is None or found[1] < best[1] else best


def _hessian(cost, p: np.ndarray, h: float = 1.0) -> np.ndarray:
    """The Hessian of `cost` at p [px] by central differences of its gradient (step h px)."""
    H = np.empty((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        H[:, i] = (cost(p + e)[1] - cost(p - e)[1]) / (2 * h)
    return 0.5 * (H + H.T)


def _positive_definite(H: np.ndarray) -> np.ndarray:
    """H with its eigenvalues' magnitudes, floored at 1e-3 of the largest (identity if none is finite)."""
    if not np.all(np.isfinite(H)):
        return np.eye(3)
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    lam = np.abs(lam)
    lam = np.maximum(lam, max(1e-3 * lam.max(), 1e-12))
    return (V * lam) @ V.T


def _within_itself(R: np.ndarray, windows) -> float:
    """The 1-sigma [rad] of a rotation R known only to within itself and the contrast peak's width
    (FOCUS_STEP_PX over the windows)."""
    return float(np.hypot(np.linalg.norm(matrix_to_rotvec(R)), _angle(windows, lambda w: FOCUS_STEP_PX)))


def _curvature_covariance(H: np.ndarray) -> np.ndarray | None:
    """From the Hessian H [per px^2] of the cost (minus the contrast over that at no motion) at
    its minimum: the covariance SIGMA_SCALE^2 H^-1 [px^2] of the optimum (None where it is not a
    minimum). Its RMS sigma over the axes, sqrt(trace / 3), is SIGMA_SCALE times the RMS
    curvature radius."""
    if not np.all(np.isfinite(H)):
        return None
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    if np.any(lam <= 0):
        return None
    return SIGMA_SCALE**2 * (V / lam) @ V.T


def _integrated(windows) -> tuple[np.ndarray, np.ndarray | None]:
    """R_{k-1}_{k}, the product of the windows' Exp(omega dt) in time order (dt the span each
    stands for), and its covariance [rad^2] in the convention of RelativeRotation (the right
    perturbation in frame k: R_true = R Exp(delta)); None where a window has none.

    To first order, an error e of a window's omega (covariance C [(rad/s)^2]) turns its factor
    into Exp(omega dt) Exp(dt e) (the right Jacobian of Exp at omega dt taken as the identity:
    its first-order term is half that angle, a few per cent for a window's few degrees), and
    carried past the windows after it (A, their product) into R Exp(A^T dt e): the covariance
    is the sum over the windows of dt^2 A^T C A. Dropping the A (summing the windows' covariances
    as they are) is the same to first order in the windows' turns, which is as far as
    independent per-window errors are a model of them anyway."""
    factors = [rotvec_to_matrix(w.omega * (w.t1 - w.t0)) for w in windows]
    R = np.eye(3)
    for factor in factors:
        R = R @ factor
    if any(w.covariance is None for w in windows):
        return R, None
    covariance, after = np.zeros((3, 3)), np.eye(3)
    for w, factor in zip(reversed(windows), reversed(factors)):
        covariance += (w.t1 - w.t0) ** 2 * after.T @ w.covariance @ after
        after = factor @ after
    return R, covariance


def _bounded(covariance: np.ndarray | None, floor_rad: float) -> np.ndarray:
    """`covariance` [rad^2] with every axis's sigma at least floor_rad and at most FLAT_SIGMA_RAD
    (its eigenvalues clipped); FLAT_SIGMA_RAD on every axis where there is none."""
    if covariance is None or not np.all(np.isfinite(covariance)):
        return FLAT_SIGMA_RAD**2 * np.eye(3)
    lam, V = np.linalg.eigh(0.5 * (covariance + covariance.T))
    return (V * np.clip(lam, min(floor_rad, FLAT_SIGMA_RAD) ** 2, FLAT_SIGMA_RAD**2)) @ V.T
